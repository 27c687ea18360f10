"""Result types of the Allan-deviation engines (rate in deg/h, tau in s)."""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from fogmon.davar.confidence import CONFIDENCE, chi2_factors

__all__ = ["CONFIDENCE", "AdevResult", "DadevResult"]


@dataclass(frozen=True)
class AdevResult:
    """Overlapping Allan deviation of one record or window.

    Arrays over taus: ``tau_s`` (s), ``m`` (averaging factor, tau = m / sample_rate_hz),
    ``adev_dph`` (deg/h; NaN where no valid term), ``lo_dph``/``hi_dph`` (two-sided
    ``confidence`` interval, deg/h), ``edf`` (equivalent degrees of freedom), ``n_terms``
    (valid overlapping terms). Scalars: ``sample_rate_hz`` (Hz), ``n_samples`` (samples in the
    record, valid or not), ``confidence`` (CONFIDENCE = 1 sigma)."""

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


@dataclass(frozen=True)
class DadevResult:
    """Dynamic Allan deviation: one overlapping ADEV per window.

    ``t_s`` (s, window-centre times, shape T), ``end_index`` (index of each window's last
    sample, T), ``tau_s``/``m`` (M), ``adev_dph`` (deg/h), ``edf``, ``n_terms`` (T x M);
    ``sample_rate_hz`` (Hz), ``window_s``, ``hop_s`` (s), ``confidence``. The interval
    ``lo_dph``/``hi_dph`` (deg/h, T x M; chi-square at ``confidence`` for each entry's
    EDF) is formed when first read: at small hops a push emits a window per sample and
    most users read a few of them (``window(i)`` forms only row i's)."""

    t_s: np.ndarray
    end_index: np.ndarray
    tau_s: np.ndarray
    m: np.ndarray
    adev_dph: np.ndarray
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
        f_lo, f_hi = self._factors
        r = i if len(f_lo) > 1 else 0
        adev = self.adev_dph[i]
        return AdevResult(self.tau_s, self.m, adev, adev * f_lo[r], adev * f_hi[r], self.edf[i], self.n_terms[i],
                          self.sample_rate_hz, self.window_samples, self.confidence)
