"""Decoded samples as a codec hands them over, before they are put on the sample grid.

A codec (KVH binary, DSP-3000 ASCII, generic lines, CAN/DBC) turns bytes or frames into
``Frames``: one entry per frame received, in arrival order, already in fogmon units
(rate in deg/h, aux channels in the units their names say). ``seq`` is the device's
sequence counter, or -1 where the protocol has none."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Frames:
    """``seq`` (int64, -1 = no counter), ``rate_dph`` (deg/h), ``valid`` (device said the
    sample is good), ``aux`` channels by name; all of equal length."""

    seq: np.ndarray
    rate_dph: np.ndarray
    valid: np.ndarray
    aux: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.seq)

    @staticmethod
    def from_lists(seq, rate_dph, valid, aux: dict | None = None) -> "Frames":
        return Frames(np.asarray(seq, dtype=np.int64).reshape(-1),
                      np.asarray(rate_dph, dtype=np.float64).reshape(-1),
                      np.asarray(valid, dtype=bool).reshape(-1),
                      {k: np.asarray(v, dtype=np.float64).reshape(-1) for k, v in (aux or {}).items()})

    @staticmethod
    def empty(aux_names=()) -> "Frames":
        return Frames.from_lists([], [], [], {k: [] for k in aux_names})

    @staticmethod
    def concat(parts: list["Frames"], aux_names=()) -> "Frames":
        if not parts:
            return Frames.empty(aux_names)
        if len(parts) == 1:
            return parts[0]
        return Frames(np.concatenate([p.seq for p in parts]),
                      np.concatenate([p.rate_dph for p in parts]),
                      np.concatenate([p.valid for p in parts]),
                      {k: np.concatenate([p.aux[k] for p in parts]) for k in parts[0].aux})
