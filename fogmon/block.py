"""The one sample type that flows from every source to every engine and sink.

A Block is a run of consecutive samples on the sensor's uniform sample grid. A sample
that was lost (missing sequence number, time gap) or flagged invalid by the sensor is
*present* in the block with ``valid == False`` and ``rate_dph`` NaN, so the grid stays
uniform and the engines exclude exactly the terms that span it: gaps are flags, never
silently joined.

Several axes (a three-axis IMU): ``axes`` names them and ``rate_dph``/``valid`` are 2-D,
one column per axis (shape (n, len(axes))); aux channels are shared by all axes unless
named ``<name>_<axis>`` (``temp_c_z``). ``block.axis(name)`` is the one-axis view every
one-axis engine takes. A one-axis block has ``axes == ()`` and 1-D arrays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fogmon.errors import FogmonError


def is_axis_name(name: object) -> bool:
    """An axis name is ASCII letters and digits (it becomes part of column names)."""
    return isinstance(name, str) and name.isascii() and name.isalnum()


def parse_axes(text: str) -> tuple[str, ...]:
    """Axis names from ``axis`` text: one name or a comma list (``x,y``); FogmonError
    for an empty, repeated or non-letters/digits name."""
    names = tuple(a.strip() for a in text.split(","))
    for a in names:
        if not is_axis_name(a):
            raise FogmonError(f"`axis` {text}: an axis name is letters and digits, got {a!r}")
    if len(set(names)) < len(names):
        raise FogmonError(f"`axis` {text}: an axis is named twice")
    return names


def axis_aux(aux: dict[str, np.ndarray], axes: tuple[str, ...], name: str) -> dict[str, np.ndarray]:
    """The aux channels axis ``name`` sees: the shared ones, and its own ``<ch>_<name>``
    as ``<ch>`` (the ``<ch>_<other axis>`` channels of the other axes left out)."""
    own = {k[: -len(name) - 1]: v for k, v in aux.items() if k.endswith("_" + name)}
    others = tuple("_" + a for a in axes if a != name)
    shared = {k: v for k, v in aux.items() if not k.endswith("_" + name) and not k.endswith(others)}
    return {**shared, **own}


def select_aux(aux: dict[str, np.ndarray], axes: tuple[str, ...], names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The aux channels of axes ``names`` of ``axes``: all but the own ``<ch>_<axis>``
    channels of the axes left out."""
    dropped = tuple("_" + a for a in axes if a not in names)
    return {k: v for k, v in aux.items() if not dropped or not k.endswith(dropped)}


@dataclass(frozen=True, slots=True)
class Event:
    """Something that happened in a source or engine: gap, CRC error, reconnect, jump.

    ``t_s`` is recording time in s; ``kind`` a short machine name (``gap``,
    ``crc_error``, ``disconnect``, ``reconnect``, ``coef_jump``...); ``message`` one
    human-readable line; ``axis`` the axis it concerns ("" for the whole stream or a
    one-axis one)."""

    t_s: float
    kind: str
    message: str
    axis: str = ""


@dataclass(frozen=True, slots=True)
class Block:
    """Samples ``t_s`` (s, recording time), ``rate_dph`` (deg/h), ``valid`` (bool) and
    auxiliary channels by name (``temp_c`` deg C, ``rot_dps`` deg/s, ``vib_g`` g,
    ``depth_m`` m, anything else as recorded), all of equal length; plus the events
    the source saw while producing them. With ``axes``, ``rate_dph`` and ``valid`` have
    one column per axis."""

    t_s: np.ndarray
    rate_dph: np.ndarray
    valid: np.ndarray
    aux: dict[str, np.ndarray] = field(default_factory=dict)
    events: tuple[Event, ...] = ()
    axes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.t_s)
        if len(self.rate_dph) != n or len(self.valid) != n:
            raise ValueError("Block arrays must have equal length")
        shape = (n, len(self.axes)) if self.axes else (n,)
        if self.rate_dph.shape != shape or self.valid.shape != shape:
            raise ValueError(f"Block rate_dph/valid must have shape {shape} for axes {self.axes}")
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

    def axis(self, name: str) -> Block:
        """The one-axis view of axis ``name`` (its rate and valid column, its aux as in
        ``axis_aux``); a one-axis block is returned as it is."""
        if not self.axes:
            return self
        j = self.axes.index(name)
        return Block(self.t_s, self.rate_dph[:, j], self.valid[:, j], axis_aux(self.aux, self.axes, name),
                     self.events)

    def select(self, names: tuple[str, ...]) -> Block:
        """Axes ``names`` only, in that order: one name gives the one-axis view
        ``axis(name)``; several a block of those columns, without the aux channels of
        the axes left out (``<ch>_<axis>``)."""
        if len(names) == 1:
            return self.axis(names[0])
        cols = [self.axes.index(a) for a in names]
        return Block(self.t_s, self.rate_dph[:, cols], self.valid[:, cols], select_aux(self.aux, self.axes, names),
                     self.events, tuple(names))

    def slice(self, start: int, stop: int) -> Block:
        """Samples ``start:stop``, with the events that fall in their time span (the
        first slice also takes events before it, the last those after it)."""
        n = len(self)
        t0 = self.t_s[start] if start > 0 else -math.inf
        t1 = self.t_s[stop] if stop < n else math.inf
        ev = tuple(e for e in self.events if t0 <= e.t_s < t1)
        return Block(self.t_s[start:stop], self.rate_dph[start:stop], self.valid[start:stop],
                     {k: v[start:stop] for k, v in self.aux.items()}, ev, self.axes)

    @staticmethod
    def concat(blocks: list[Block]) -> Block:
        """Consecutive blocks of one grid (and the same axes) as one block."""
        if len(blocks) == 1:
            return blocks[0]
        return Block(np.concatenate([b.t_s for b in blocks]), np.concatenate([b.rate_dph for b in blocks]),
                     np.concatenate([b.valid for b in blocks]),
                     {k: np.concatenate([b.aux[k] for b in blocks]) for k in blocks[0].aux},
                     tuple(e for b in blocks for e in b.events), blocks[0].axes)

    @staticmethod
    def make(t_s, rate_dph, valid=None, aux=None, events=(), axes: tuple[str, ...] = ()) -> Block:
        """Build a block from array-likes; ``valid`` defaults to ``isfinite(rate)``;
        a non-finite rate is always invalid. With ``axes``, ``rate_dph`` (and ``valid``)
        are (n, len(axes))."""
        t = np.asarray(t_s, dtype=np.float64)
        r = np.asarray(rate_dph, dtype=np.float64)
        v = np.isfinite(r)
        if valid is not None:
            v &= np.asarray(valid, dtype=bool)
        a = {k: np.asarray(x, dtype=np.float64) for k, x in (aux or {}).items()}
        return Block(t, r, v, a, tuple(events), tuple(axes))
