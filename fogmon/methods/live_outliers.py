"""Live outlier rejection: the in-orbit paper's Pauta criterion, made robust and causal.

The Pauta criterion rejects samples farther than k standard deviations from the mean. On
a live stream with spikes, drift and quantized rates the mean and standard deviation are
replaced by robust, causal estimates that use only earlier samples:

- the level a sample is judged against is predicted from the ``2 LEVEL_N`` grid samples
  before it: the median of the last LEVEL_N, moved along the slope between it and the
  median of the LEVEL_N before (an invalid sample counts as the last valid value before
  it). It follows drift and smooth platform motion, and a few earlier outliers cannot
  move it;
- the noise of one sample (deg/h) is the trimmed standard deviation of first differences
  (fogmon.motion.robust_sigma_of_diffs) over the ``REFERENCE_N`` grid samples before the
  current segment of ``SEGMENT_N`` samples; it is refreshed once per segment.

Both depend only on positions on the sample grid, so the decision for a sample does not
depend on how the stream was cut into blocks. With Gaussian noise a sample is rejected
with probability ``false_rejection(k)`` (k = 7: 5.8e-10 per sample, one in 20 days at
1 kHz), so the statistics of a clean gyro are unchanged.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import median_filter
from scipy.stats import norm

from fogmon.motion import robust_sigma_of_diffs

#: Default rejection threshold, in sigmas of one sample.
DEFAULT_K = 7.0
#: Samples per median of the level prediction (odd: one middle sample).
LEVEL_N = 15
#: The level is the recent median moved along the slope by this many samples: from the
#: recent median's centre to the judged sample.
_LEAD = (LEVEL_N + 1) / 2
#: Samples whose difference scatter gives the noise of one sample.
REFERENCE_N = 4096
#: The noise estimate is refreshed every SEGMENT_N samples.
SEGMENT_N = 256
#: No decision before this many valid reference samples.
MIN_REFERENCE_N = 64


def level_variance() -> float:
    """Variance of the deviation of a white-noise sample from its predicted level, in
    units of the sample variance: 1 + the level's variance, the two medians' variances
    (pi / 2) / LEVEL_N each weighted by (1 + _LEAD / LEVEL_N) and _LEAD / LEVEL_N."""
    w = _LEAD / LEVEL_N
    return 1.0 + math.pi / (2 * LEVEL_N) * ((1 + w) ** 2 + w ** 2)


def false_rejection(k: float) -> float:
    """Probability (per sample) that Gaussian white noise is rejected at threshold ``k``."""
    return 2.0 * float(norm.sf(k / math.sqrt(level_variance())))


class OutlierRejector:
    """Decides, block by block, which valid samples are outliers (``push`` returns the
    mask). ``rejected`` counts them."""

    def __init__(self, k: float = DEFAULT_K) -> None:
        if not (math.isfinite(k) and k > 0):
            raise ValueError(f"outlier threshold k must be a finite number > 0, got {k}")
        self.k = float(k)
        self.rejected = 0
        self._hist = np.empty(0)      # last REFERENCE_N grid samples (NaN = invalid)
        self._pos = 0                 # grid index of the next sample
        self._sigma = float("nan")    # noise of one sample for the current segment, deg/h

    def push(self, rate_dph: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Mask of the samples of this block that are outliers (only valid samples are)."""
        y = np.where(np.asarray(valid, bool), np.asarray(rate_dph, float), np.nan)
        n = len(y)
        if n == 0:
            return np.zeros(0, bool)
        hist_n = len(self._hist)
        allv = np.concatenate((self._hist, y))
        level = _predicted_level(allv)[-n:]
        sigma = np.empty(n)
        start = 0
        while start < n:  # the noise estimate is refreshed at grid multiples of SEGMENT_N
            g = self._pos + start
            if g % SEGMENT_N == 0:
                ref = allv[max(hist_n + start - REFERENCE_N, 0):hist_n + start]
                ok = np.isfinite(ref).sum() >= MIN_REFERENCE_N
                self._sigma = float(robust_sigma_of_diffs(ref[None, :])[0]) if ok else float("nan")
            end = min(n, start + SEGMENT_N - g % SEGMENT_N)
            sigma[start:end] = self._sigma
            start = end
        with np.errstate(invalid="ignore"):
            out = np.abs(y - level) > self.k * sigma
        self._hist = allv[-REFERENCE_N:]
        self._pos += n
        self.rejected += int(out.sum())
        return out


def _predicted_level(x: np.ndarray) -> np.ndarray:
    """For each sample of ``x`` (NaN = invalid), the level predicted from the 2 LEVEL_N
    samples before it, an invalid one replaced by the last valid value before it (the
    first valid value where there is none yet)."""
    idx = np.where(np.isfinite(x), np.arange(len(x)), -1)
    np.maximum.accumulate(idx, out=idx)
    if idx[-1] < 0:
        return np.full(len(x), np.nan)
    filled = np.where(idx >= 0, x[np.maximum(idx, 0)], x[np.argmax(idx >= 0)])
    prior = np.concatenate((np.full(2 * LEVEL_N, filled[0]), filled[:-1]))  # prior[i + 2N] = filled[i - 1]
    # med[j] = median of prior[j : j + LEVEL_N]
    med = median_filter(prior, size=LEVEL_N, mode="nearest", origin=-(LEVEL_N // 2))
    recent, older = med[LEVEL_N:LEVEL_N + len(x)], med[:len(x)]  # filled[i-N : i], filled[i-2N : i-N]
    return recent + (recent - older) * (_LEAD / LEVEL_N)
