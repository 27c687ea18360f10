"""Batch overlapping Allan deviation of a whole record (oadev) and of sliding windows
(dadev, the dynamic Allan deviation), rate in deg/h, time in s.

For each averaging factor m the squared overlapping terms are accumulated in one
compensated cumulative sum and window sums are read off by differencing: O(N x M) for any
number of windows and any hop. Prefix sums are double-double of (rate - median), so a large
bias costs no precision; invalid samples (``valid`` False or NaN) exclude exactly the terms
spanning them; a huge sample (|rate| > 1e8 deg/h or infinite) enters no sum and makes
the terms spanning it +inf, so the windows holding it report +inf and no other window
changes.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from fogmon.davar import kernels
from fogmon.davar.confidence import chi2_bounds, edf_effective, edf_full
from fogmon.davar.fit import dominant_alpha, fit_avar
from fogmon.davar.result import CONFIDENCE, AdevResult, DadevResult
from fogmon.davar.taus import tau_grid
from fogmon.errors import FogmonError


def _prepare(rate_dph, valid) -> tuple[np.ndarray, np.ndarray]:
    y = np.ascontiguousarray(rate_dph, dtype=np.float64)
    if y.ndim != 1:
        raise FogmonError(f"rate_dph must be one-dimensional, got shape {y.shape}")
    ok = ~np.isnan(y)  # +-inf are huge samples, not gaps
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != y.shape:
            raise FogmonError(f"valid mask shape {valid.shape} does not match rate_dph shape {y.shape}")
        ok &= valid
    return y, ok


def reference_level(y: np.ndarray, ok: np.ndarray) -> float:
    """Level (deg/h) subtracted before the prefix sums: the median of the valid samples
    within the ceiling (0 without any)."""
    ref = kernels.reference_level(y, ok)
    return 0.0 if np.isnan(ref) else float(ref)


def _samples(seconds: float, rate_hz: float, what: str) -> int:
    n = int(round(seconds * rate_hz))
    if not np.isfinite(seconds) or n < 1:
        raise FogmonError(f"{what} must be at least one sample period, got {seconds} s")
    return n


def row_alpha(sums, counts, m, n_samples: int) -> np.ndarray:
    """Noise type alpha per tau for one window: the dominant term of an IEEE-952 fit to
    its Allan variance (sums of squared terms and valid-term counts over m)."""
    counts = np.asarray(counts)
    with np.errstate(invalid="ignore", divide="ignore"):
        avar = np.where(counts > 0, np.maximum(sums, 0.0) / (2.0 * counts), np.nan)
    tau_m = np.asarray(m, dtype=np.float64)  # tau in units of tau0: alpha does not depend on the unit
    return dominant_alpha(np.nan_to_num(fit_avar(tau_m, avar, m, counts, n_samples)[0]), tau_m)


def alpha_rows(sums, counts, ends, m, n_samples: int, every: int, prev=None):
    """Noise type per (window, tau) for windows ending at ``ends``: refitted (row_alpha)
    on the first window at least ``every`` samples after the previous refit and held in
    between, so batch and streaming engines pick the same windows. ``prev`` is
    (alpha, end) of the last refit before these windows, or None. Returns
    (alpha (T x M), (alpha, end) of the last refit)."""
    alpha_now, end_now = (np.zeros(len(m), dtype=np.int64), None) if prev is None else prev
    if len(ends) == 0:
        return np.zeros((0, len(m)), dtype=np.int64), (alpha_now, end_now)
    seg_start, seg_alpha = [0], [alpha_now]
    r = 0 if end_now is None else int(np.searchsorted(ends, end_now + every))
    while r < len(ends):
        alpha_now, end_now = row_alpha(sums[r], counts[r], m, n_samples), int(ends[r])
        seg_start.append(r)
        seg_alpha.append(alpha_now)
        r = int(np.searchsorted(ends, end_now + every))
    seg = np.searchsorted(np.array(seg_start), np.arange(len(ends)), side="right") - 1
    return np.array(seg_alpha, dtype=np.int64)[seg], (alpha_now, end_now)


@lru_cache(maxsize=256)
def _gapless_tables(alpha: tuple, m: tuple, n_samples: int, confidence: float):
    """Gap-free EDF per tau and the chi2 factors lo/sigma, hi/sigma (cached: streaming
    asks for the same ones block after block)."""
    edf = edf_full(np.array(alpha), np.array(m), n_samples)
    f_lo, f_hi = chi2_bounds(np.ones_like(edf), edf, confidence)
    return edf, f_lo, f_hi


def statistics(sums, counts, m, n_samples: int, alpha=None, confidence: float = CONFIDENCE):
    """(adev_dph, lo_dph, hi_dph, edf) from sums of squared terms and valid-term counts
    (shape (..., M)) of windows of ``n_samples``. ``alpha`` (noise type per tau, scalar,
    (M,) or (..., M)) defaults to the dominant term of an IEEE-952 fit of each window."""
    shape = np.shape(sums)
    nm = len(m)
    sums = np.asarray(sums, dtype=np.float64).reshape(-1, nm)
    counts = np.asarray(counts, dtype=np.int64).reshape(-1, nm)
    if alpha is None:
        alpha = np.array([row_alpha(s, c, m, n_samples) for s, c in zip(sums, counts)], dtype=np.int64).reshape(shape)
    alpha = np.broadcast_to(np.asarray(alpha, dtype=np.int64), shape).reshape(-1, nm)
    # alpha is piecewise constant over windows: one EDF row and one chi2 table per run
    new_run = np.ones(len(alpha), dtype=bool)
    new_run[1:] = np.any(alpha[1:] != alpha[:-1], axis=1)
    run = np.cumsum(new_run) - 1
    tables = [_gapless_tables(tuple(a), tuple(m), int(n_samples), float(confidence)) for a in alpha[new_run]]
    edf_gapless, f_lo, f_hi = (np.array([t[i] for t in tables]).reshape(-1, nm) for i in range(3))
    full = n_samples - 2 * np.asarray(m, dtype=np.int64) + 1
    adev, lo, hi, edf, gapped = kernels.frame_stats(sums, counts, run, full, edf_gapless, f_lo, f_hi)
    if gapped.any():
        edf[gapped] = edf_effective(edf[gapped], np.broadcast_to(m, edf.shape)[gapped], n_samples, counts[gapped])
        lo[gapped], hi[gapped] = chi2_bounds(adev[gapped], edf[gapped], confidence)
    return tuple(x.reshape(shape) for x in (adev, lo, hi, edf))


def oadev(rate_dph, rate_hz: float, taus="octave", valid=None, confidence: float = CONFIDENCE,
          alpha=None) -> AdevResult:
    """Overlapping Allan deviation (deg/h) of a rate record ``rate_dph`` (deg/h) sampled at
    ``rate_hz`` (Hz). ``taus``: see :func:`fogmon.davar.taus.tau_grid`. ``valid``: optional
    mask; NaN samples are invalid too. Bounds: chi-square at ``confidence`` with Greenhall
    EDF for noise type ``alpha`` (default: the dominant term of an IEEE-952 fit)."""
    y, ok = _prepare(rate_dph, valid)
    n = len(y)
    m = tau_grid(rate_hz, n, taus)
    hi_, lo_, bad = kernels.prefix_sums_dd(y, ok, reference_level(y, ok))
    sums, counts = kernels.window_sums(hi_, lo_, bad, m, np.zeros(1, np.int64), n)
    adev, lo, hi, edf = statistics(sums[0], counts[0], m, n, alpha, confidence)
    return AdevResult(m / rate_hz, m, adev, lo, hi, edf, counts[0], float(rate_hz), n, confidence)


def dadev(rate_dph, rate_hz: float, window_s: float, hop_s: float | None = None, taus="octave",
          valid=None, confidence: float = CONFIDENCE, t0_s: float = 0.0, alpha=None) -> DadevResult:
    """Dynamic Allan deviation: overlapping ADEV (deg/h) of every window of ``window_s`` s,
    windows starting every ``hop_s`` s (default window_s / 4) from the first sample at
    time ``t0_s`` (s); only complete windows. Taus limited to window / 4. The default
    ``alpha`` is refitted every max(hop, window / 4) samples (see :func:`alpha_rows`)."""
    y, ok = _prepare(rate_dph, valid)
    w = _samples(window_s, rate_hz, "window_s")
    hop = _samples(window_s / 4.0 if hop_s is None else hop_s, rate_hz, "hop_s")
    m = tau_grid(rate_hz, w, taus)
    starts = np.arange(0, len(y) - w + 1, hop, dtype=np.int64)
    hi_, lo_, bad = kernels.prefix_sums_dd(y, ok, reference_level(y, ok))
    sums, counts = kernels.window_sums(hi_, lo_, bad, m, starts, w)
    end = starts + w - 1
    if alpha is None:
        alpha, _ = alpha_rows(sums, counts, end, m, w, max(hop, w // 4))
    adev, lo, hi, edf = statistics(sums, counts, m, w, alpha, confidence)
    return DadevResult(t0_s + (starts + (w - 1) / 2.0) / rate_hz, end, m / rate_hz, m, adev, lo, hi, edf,
                       counts, float(rate_hz), w / rate_hz, hop / rate_hz, confidence)
