"""Platform motion: stretches where the measured rate moves far beyond the sensor's noise
and nothing (no ``rot_dps`` reference) says why: a turntable, a vehicle, a person
handling the unit, the ground shaking. Noise coefficients fitted over such a stretch
describe the motion, not the gyro (a hand-turned FOG "identifies" R = 7e9 deg/h^2), so
explain and the live pipeline keep them out of their fits and say so.

The test, on blocks of ``block_samples(rate_hz)`` samples: a block moves when its mean
rate departs from the local reference (a running median of block means over
``REFERENCE_S``) by more than both

- ``K_BLOCK`` x the block-to-block scatter of a quiet block mean (so it is not chance),
- ``K_SAMPLE`` x the noise of a single sample (so it is not a slow wander or a small
  sway that the noise analysis models itself: vibration lines, bias instability).

Both scales are estimated from the quiet part of the recording itself (low quantiles, so
motion over most of the record still leaves them right). Single-sample outliers (glitches)
are not motion: samples beyond ``K_OUTLIER`` sample-sigmas of their block's median are left
out of the block mean. A constant-rate plateau longer than half of ``REFERENCE_S`` cannot
be told from a bias change and is not flagged (the reference follows it).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter

#: a block moves beyond K_BLOCK x the quiet scatter of block means ...
K_BLOCK = 8.0
#: ... and beyond K_SAMPLE x the noise of one sample (both must hold)
K_SAMPLE = 3.0
#: samples beyond this many sample-sigmas from their block median are outliers, not motion
K_OUTLIER = 10.0
#: the local reference: running median of block means over this long (s)
REFERENCE_S = 300.0
#: flagged blocks closer than this (s, or two blocks) form one span
MERGE_S = 10.0
#: the quiet scales are low quantiles over blocks (motion may cover most of a record)
QUIET_QUANTILE = 0.25


@dataclass(frozen=True)
class MotionSpan:
    """A stretch of platform motion: recording time ``t_start_s`` .. ``t_end_s`` (s) and
    the largest departure of a block-mean rate from its reference, ``peak_dph`` (deg/h)."""
    t_start_s: float
    t_end_s: float
    peak_dph: float


def block_samples(rate_hz: float) -> int:
    """Samples per test block: 0.25 s, at least 32 samples."""
    return max(32, int(round(0.25 * rate_hz)))


def _robust_sigma_of_diffs(y: np.ndarray) -> np.ndarray:
    """Per row of ``y`` (blocks x samples): sigma of one sample from the MAD of first
    differences (insensitive to a slow trend and to a few outliers)."""
    d = np.diff(y, axis=1)
    med = np.nanmedian(d, axis=1, keepdims=True)
    return np.nanmedian(np.abs(d - med), axis=1) / 0.6745 / np.sqrt(2.0)


def find_motion(t_s: np.ndarray, rate_dph: np.ndarray, valid: np.ndarray, rate_hz: float) -> list[MotionSpan]:
    """The platform-motion spans of a recording on a uniform grid (``t_s`` in s,
    ``rate_dph`` in deg/h with the reference rotation already removed, ``valid`` False
    where there is no sample), in time order; empty for a stationary recording."""
    m = block_samples(rate_hz)
    nb = len(rate_dph) // m
    if nb < 4:
        return []
    y = np.where(valid, rate_dph, np.nan)[:nb * m].reshape(nb, m).astype(np.float64)
    enough = np.sum(np.isfinite(y), axis=1) >= m // 2
    if np.count_nonzero(enough) < 4:
        return []
    with warnings.catch_warnings():          # all-NaN blocks (gaps) are expected
        warnings.simplefilter("ignore", RuntimeWarning)
        sigma_1 = float(np.nanquantile(_robust_sigma_of_diffs(y)[enough], QUIET_QUANTILE))
        med = np.nanmedian(y, axis=1)
        mean = med.copy()
        if sigma_1 > 0:         # outliers out of the mean; a block in fast motion keeps its median
            kept = np.where(np.abs(y - med[:, None]) > K_OUTLIER * sigma_1, np.nan, y)
            n_kept = np.sum(np.isfinite(kept), axis=1)
            ok = n_kept >= m // 4
            mean[ok] = np.nanmean(kept[ok], axis=1)
        else:
            mean = np.nanmean(y, axis=1)
    mean[~enough] = np.nan
    idx = np.flatnonzero(np.isfinite(mean))
    mu = mean[idx]
    steps = np.abs(np.diff(mu))
    s_block = float(np.quantile(steps, QUIET_QUANTILE)) / 0.3186 / np.sqrt(2.0) if len(steps) else 0.0
    w = max(5, int(REFERENCE_S * rate_hz / m)) | 1
    ref = median_filter(mu, size=w, mode="nearest")
    dev = np.abs(mu - ref)
    limit = max(K_BLOCK * s_block, K_SAMPLE * sigma_1)
    if not limit > 0:                  # a constant record: anything that changes moves
        limit = 0.0
    moving = idx[dev > limit]
    if not len(moving):
        return []
    peak = np.zeros(nb)
    peak[idx] = dev
    gap = max(2, int(np.ceil(MERGE_S * rate_hz / m)))
    spans, start, end = [], moving[0], moving[0]
    for b in moving[1:]:
        if b - end > gap:
            spans.append((start, end))
            start = b
        end = b
    spans.append((start, end))
    dt = 1.0 / rate_hz
    t0 = float(t_s[0])
    out = []
    for a, b in spans:          # one block of margin each side: onsets begin inside the neighbours
        a, b = max(0, a - 1), min(nb - 1, b + 1)
        out.append(MotionSpan(t0 + a * m * dt, min(t0 + ((b + 1) * m - 1) * dt, float(t_s[-1])),
                              float(peak[a:b + 1].max())))
    return out


def motion_mask(t_s: np.ndarray, spans: list[MotionSpan]) -> np.ndarray:
    """True for the samples at ``t_s`` (s) inside any of ``spans``."""
    mask = np.zeros(len(t_s), dtype=bool)
    for s in spans:
        mask |= (t_s >= s.t_start_s) & (t_s <= s.t_end_s)
    return mask
