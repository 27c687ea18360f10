"""The one sample type that flows from every source to every engine and sink.

A Block is a run of consecutive samples on the sensor's uniform sample grid. A sample
that was lost (missing sequence number, time gap) or flagged invalid by the sensor is
*present* in the block with ``valid == False`` and ``rate_dph`` NaN, so the grid stays
uniform and the engines exclude exactly the terms that span it: gaps are flags, never
silently joined.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, slots=True)
class Event:
    """Something that happened in a source or engine: gap, CRC error, reconnect, jump.

    ``t_s`` is recording time in s; ``kind`` a short machine name (``gap``,
    ``crc_error``, ``disconnect``, ``reconnect``, ``coef_jump``...); ``message`` one
    human-readable line."""

    t_s: float
    kind: str
    message: str


@dataclass(frozen=True, slots=True)
class Block:
    """Samples ``t_s`` (s, recording time), ``rate_dph`` (deg/h), ``valid`` (bool) and
    auxiliary channels by name (``temp_c`` deg C, ``rot_dps`` deg/s, ``vib_g`` g,
    ``depth_m`` m, anything else as recorded), all of equal length; plus the events
    the source saw while producing them."""

    t_s: np.ndarray
    rate_dph: np.ndarray
    valid: np.ndarray
    aux: dict[str, np.ndarray] = field(default_factory=dict)
    events: tuple[Event, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.t_s)
        if len(self.rate_dph) != n or len(self.valid) != n:
            raise ValueError("Block arrays must have equal length")
        for name, a in self.aux.items():
            if len(a) != n:
                raise ValueError(f"Block aux channel {name!r} has the wrong length")

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def error_rate_dph(self) -> np.ndarray:
        """The gyro's error against the reference rotation (docs/formats.md: a gyro should read
        3600 x rot_dps), deg/h: ``rate_dph - 3600 rot_dps``; ``rate_dph`` itself when the
        block has no ``rot_dps``. NaN where either is unknown."""
        if "rot_dps" not in self.aux:
            return self.rate_dph
        return self.rate_dph - 3600.0 * self.aux["rot_dps"]

    @staticmethod
    def make(t_s, rate_dph, valid=None, aux=None, events=()) -> Block:
        """Build a block from array-likes; ``valid`` defaults to ``isfinite(rate)``;
        a non-finite rate is always invalid."""
        t = np.asarray(t_s, dtype=np.float64)
        r = np.asarray(rate_dph, dtype=np.float64)
        v = np.isfinite(r)
        if valid is not None:
            v &= np.asarray(valid, dtype=bool)
        a = {k: np.asarray(x, dtype=np.float64) for k, x in (aux or {}).items()}
        return Block(t, r, v, a, tuple(events))
