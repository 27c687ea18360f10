"""Result types of the Allan-deviation engines (rate in deg/h, tau in s)."""
from __future__ import annotations

import threading
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from fogmon.davar.confidence import CONFIDENCE, chi2_factors

__all__ = ["CONFIDENCE", "AdevResult", "DadevResult", "WindowSums"]


@dataclass(frozen=True)
class AdevResult:
    """Overlapping Allan deviation of one record or window.

    Arrays over taus: ``tau_s`` (s), ``m`` (averaging factor, tau = m / sample_rate_hz),
    ``adev_dph`` (deg/h; NaN where no valid term), ``lo_dph``/``hi_dph`` (two-sided
    ``confidence`` interval, deg/h), ``edf`` (equivalent degrees of freedom), ``n_terms``
    (valid overlapping terms). Scalars: ``sample_rate_hz`` (Hz), ``n_samples`` (samples in the
    record, valid or not), ``confidence`` (CONFIDENCE = 1 sigma), ``ramp_k``: where the EDF
    took the record's rate ramp as deterministic (``batch.record_statistics``), the random
    walk it took beside it, A_K ((deg/h)^2 s^-1, from the detrended record); NaN where it
    took the ramp as random-walk noise or has no ramp reading (DADEV windows, Greenhall's EDF)."""

    tau_s: np.ndarray
    m: np.ndarray
    adev_dph: np.ndarray
    lo_dph: np.ndarray
    hi_dph: np.ndarray
    edf: np.ndarray
    n_terms: np.ndarray
    sample_rate_hz: float
    n_samples: int
    confidence: float = CONFIDENCE
    ramp_k: float = float("nan")


class WindowSums:
    """Sums of squared overlapping terms ((deg/h)^2, T x M) and valid-term counts (T x M;
    a read-only broadcast of one row when all windows have the same) of windows, handed
    over by the engine that made them: what a DadevResult's ``adev_dph`` is formed from
    when first read. The first read of all rows turns the sums into adev in place (no
    new array; the sums are gone then; one thread at a time); a read of some rows forms
    those alone."""

    def __init__(self, sums: np.ndarray, counts: np.ndarray):
        self._values = sums  # the sums; adev once ``_formed``
        self._counts = counts
        self._formed = False
        self._lock = threading.Lock()

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k != "_lock"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state, _lock=threading.Lock())

    def adev_dph(self, rows: slice = slice(None)) -> np.ndarray:
        """adev (deg/h) = sqrt(sums / (2 counts)) of windows ``rows`` (NaN without terms)."""
        with self._lock:
            return self._adev_dph(rows)

    def _adev_dph(self, rows: slice) -> np.ndarray:
        from fogmon.davar import window_stats  # (numba: loaded by the engine that made these sums)
        from fogmon.jit import c_array
        if self._formed:
            return self._values[rows]
        one_row = self._counts.strides[0] == 0  # a broadcast row: the kernels read that row
        counts = c_array(self._counts[:1] if one_row else self._counts[rows], np.int64)
        if rows == slice(None):
            self._values = c_array(self._values, np.float64)
            window_stats.adev_in_place(self._values, counts)
            self._formed = True
            return self._values
        sums = c_array(self._values[rows], np.float64)
        adev = np.empty(sums.shape)
        window_stats.frame_stats(sums, counts, np.zeros(sums.shape[1], np.int64), adev)
        return adev


_ADEV = "_adev_dph"  # where a DadevResult keeps its adev_dph (an array or WindowSums)


class _FormedOnRead:
    """The ``adev_dph`` field of DadevResult (a data descriptor; pickling, ``replace``
    and the dataclass's __init__, __eq__ and __repr__ see a plain field): an array, or a
    WindowSums given in its place and turned into the array when first read (then kept)."""

    def __get__(self, obj, owner=None) -> np.ndarray:
        if obj is None:
            raise AttributeError("adev_dph")  # so the dataclass gives the field no default
        value = obj.__dict__[_ADEV]
        if isinstance(value, WindowSums):
            value = obj.__dict__[_ADEV] = value.adev_dph()
        return value

    def __set__(self, obj, value) -> None:
        obj.__dict__[_ADEV] = value


@dataclass(frozen=True)
class DadevResult:
    """Dynamic Allan deviation: one overlapping ADEV per window.

    ``t_s`` (s, window-centre times, shape T), ``end_index`` (index of each window's last
    sample, T), ``tau_s``/``m`` (M), ``adev_dph`` (deg/h), ``edf``, ``n_terms`` (T x M);
    ``sample_rate_hz`` (Hz), ``window_s``, ``hop_s`` (s), ``confidence``. The interval
    ``lo_dph``/``hi_dph`` (deg/h, T x M; chi-square at ``confidence`` for each entry's
    EDF) is formed when first read, and so is ``adev_dph`` when given as the windows'
    :class:`WindowSums` (the streaming engine's push): at small hops a push emits a window
    per sample and most users read a few of them (``window(i)`` forms only row i's)."""

    t_s: np.ndarray
    end_index: np.ndarray
    tau_s: np.ndarray
    m: np.ndarray
    if TYPE_CHECKING:  # what readers get (a descriptor field without a default is beyond mypy)
        adev_dph: np.ndarray
    else:
        adev_dph: np.ndarray = _FormedOnRead()
    edf: np.ndarray
    n_terms: np.ndarray
    sample_rate_hz: float
    window_s: float
    hop_s: float
    confidence: float = CONFIDENCE

    def __len__(self) -> int:
        return len(self.t_s)

    @cached_property
    def _factors(self) -> tuple[np.ndarray, np.ndarray]:
        """chi2 interval factors of the EDF: one row when one EDF row holds for all windows."""
        return chi2_factors(self.edf, self.confidence)

    @cached_property
    def lo_dph(self) -> np.ndarray:
        """Lower end of each entry's interval (deg/h, T x M)."""
        return self.adev_dph * self._factors[0]

    @cached_property
    def hi_dph(self) -> np.ndarray:
        """Upper end of each entry's interval (deg/h, T x M)."""
        return self.adev_dph * self._factors[1]

    @property
    def window_samples(self) -> int:
        """Window length in samples."""
        return int(round(self.window_s * self.sample_rate_hz))

    def window(self, i: int) -> AdevResult:
        """The ADEV of window ``i`` as an AdevResult."""
        i = range(len(self))[i]
        f_lo, f_hi = self._factors
        r = i if len(f_lo) > 1 else 0
        held = self.__dict__[_ADEV]  # not formed yet: row i's alone
        adev = held.adev_dph(slice(i, i + 1))[0] if isinstance(held, WindowSums) else held[i]
        return AdevResult(self.tau_s, self.m, adev, adev * f_lo[r], adev * f_hi[r], self.edf[i], self.n_terms[i],
                          self.sample_rate_hz, self.window_samples, self.confidence)
