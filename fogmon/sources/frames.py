"""Decoded samples as a codec hands them over, before they are put on the sample grid.

A codec (KVH binary, DSP-3000 ASCII, generic lines, CAN/DBC) turns bytes or frames into
``Frames``: one entry per frame received, in arrival order, already in fogmon units
(rate in deg/h, aux channels in the units their names say). ``seq`` is the device's
sequence counter, or -1 where the protocol has none. ``skipped`` says whether the byte
stream was continuous up to each frame: the bytes between the end of the previous good
frame and the start of this one that belong to no good frame (0 = continuous: garbage,
CRC failures and truncated frames show here; the time base relies on it, see
fogmon.sources.grid). ``frame_bytes`` is the protocol's frame length in bytes (0 =
variable or unknown). A multi-axis codec names its ``axes`` and gives ``rate_dph`` and
``valid`` one column per axis, as fogmon.block.Block does."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Frames:
    """``seq`` (int64, -1 = no counter), ``rate_dph`` (deg/h), ``valid`` (device said the
    sample is good), ``aux`` channels by name, ``skipped`` (int64 bytes before each frame
    that belong to no good frame; None = all 0); all of equal length. ``frame_bytes``:
    bytes per frame of the protocol (0 = not fixed)."""

    seq: np.ndarray
    rate_dph: np.ndarray
    valid: np.ndarray
    aux: dict[str, np.ndarray] = field(default_factory=dict)
    skipped: np.ndarray | None = None
    frame_bytes: int = 0
    axes: tuple[str, ...] = ()

    def skipped_bytes(self) -> np.ndarray:
        """``skipped`` as an int64 array (zeros when the codec does not report it)."""
        return np.zeros(len(self.seq), np.int64) if self.skipped is None else self.skipped

    def __len__(self) -> int:
        return len(self.seq)

    @staticmethod
    def from_lists(seq, rate_dph, valid, aux: dict | None = None, skipped=None, frame_bytes: int = 0,
                   axes: tuple[str, ...] = ()) -> Frames:
        shape = (-1, len(axes)) if axes else (-1,)
        return Frames(np.asarray(seq, dtype=np.int64).reshape(-1),
                      np.asarray(rate_dph, dtype=np.float64).reshape(shape),
                      np.asarray(valid, dtype=bool).reshape(shape),
                      {k: np.asarray(v, dtype=np.float64).reshape(-1) for k, v in (aux or {}).items()},
                      None if skipped is None else np.asarray(skipped, dtype=np.int64).reshape(-1),
                      int(frame_bytes), tuple(axes))

    @staticmethod
    def empty(aux_names=(), axes: tuple[str, ...] = ()) -> Frames:
        return Frames.from_lists([], [], [], {k: [] for k in aux_names}, axes=axes)
