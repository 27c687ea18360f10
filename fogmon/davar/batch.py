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

import functools
from functools import lru_cache

import numpy as np

from fogmon.davar import kernels, record_mixture, window_stats
from fogmon.davar.confidence import chi2_bounds, edf_effective, edf_full
from fogmon.davar.fit import low_pass_taus, mixture_edf_row, quick_avar_terms
from fogmon.davar.result import CONFIDENCE, AdevResult, DadevResult
from fogmon.davar.shape import shape_applies, shape_factors
from fogmon.davar.taus import tau_grid
from fogmon.davar.theory import POWERS
from fogmon.errors import FogmonError
from fogmon.jit import c_array


def _prepare(rate_dph, valid) -> tuple[np.ndarray, np.ndarray]:
    y = c_array(rate_dph, np.float64)
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


def _samples(seconds: float, sample_rate_hz: float, what: str) -> int:
    n = int(round(seconds * sample_rate_hz))
    if not np.isfinite(seconds) or n < 1:
        raise FogmonError(f"{what} must be at least one sample period, got {seconds} s")
    return n


def _avar(sums, counts) -> np.ndarray:
    counts = np.asarray(counts)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, np.maximum(sums, 0.0) / (2.0 * counts), np.nan)


def _row_terms(sums, counts, m, n_samples: int) -> np.ndarray:
    """A_n of the quick IEEE-952 fit (``fit.quick_avar_terms``) of one window, tau in
    units of the sample period (the mixture does not depend on the unit)."""
    return quick_avar_terms(np.asarray(m, dtype=np.float64), _avar(sums, counts), m, counts, n_samples)


def _terms_edf(terms, m, n_samples: int, avar) -> np.ndarray:
    """Gap-free EDF row (1, M) of the mixture the quick-fit ``terms`` (tau in sample
    periods) predict (``fit.mixture_edf_row``); at the taus below a low-pass's peak of
    the Allan variance ``avar`` (``fit.low_pass_taus``) no more than at the peak: there
    the filter, not the noise type, sets how far apart the terms decorrelate (a flicker
    floor under a 1 Hz 4-pole filter at 100 Hz, 60 records of 3000 s: the spread of the
    Allan variances gives an EDF of 6,380 at 0.01-0.04 s, the mixture 205,000; capped at
    the peak's, 0.64-1.28 s on a noisy flat top, 2,770 in the median record: conservative
    there, exact from the peak on)."""
    return _capped_below_peak(mixture_edf_row(terms, np.asarray(m, dtype=np.float64), m, n_samples), avar)


def _capped_below_peak(edf: np.ndarray, avar) -> np.ndarray:
    """The EDF row (1, M) ``edf`` no higher at the taus below a low-pass's peak of the
    Allan variance ``avar`` (``fit.low_pass_taus``) than at the peak (``_terms_edf``)."""
    k = low_pass_taus(avar)
    if k:
        edf = edf.copy()
        edf[:k] = np.fmin(edf[:k], edf[k])
    return edf.reshape(1, -1)


def row_edf(sums, counts, m, n_samples: int) -> np.ndarray:
    """Gap-free EDF per tau (1, M) for one window: that of the noise mixture a quick
    IEEE-952 fit (``fit.quick_avar_terms``) to its Allan variance predicts (its ramp
    deterministic), exact where two terms meet (the dominant type's Greenhall EDF was 44x
    too high at 0.5 s on a 1 kHz white angle + white rate record and 9-30 % off for white
    rate noise at small m)."""
    return _terms_edf(_row_terms(sums, counts, m, n_samples), m, n_samples, _avar(sums, counts))


HOLD_Z = 3.0
"""A window whose log Allan variance is within HOLD_Z standard deviations of the last
refit's model at every tau keeps that refit's EDF row (``edf_rows``)."""


def _model_curve(a, m) -> np.ndarray:
    """Allan variance (deg/h)^2 per tau of the quick-fit terms ``a`` (tau in sample periods)."""
    return (np.asarray(m, dtype=np.float64)[:, None] ** POWERS) @ a


def _model_holds(model, sums, counts, m) -> bool:
    """The quick-fit model curve ``model`` (``_model_curve``) still describes a window:
    |ln(avar / model)| <= HOLD_Z sqrt(2 / nu + 0.1^2) at every tau with terms, nu =
    n_terms / m (about the EDF of white rate noise, lower for the others: a loose test).
    One numba call (``window_stats.model_holds``): a dozen numpy calls on 46 values cost
    ~100 us on a loaded machine between engine blocks."""
    return bool(window_stats.model_holds(model, sums, c_array(counts, np.int64), m, HOLD_Z))


def edf_rows(sums, counts, ends, m, n_samples: int, every: int, prev=None):
    """Gap-free EDF per (window, tau) for windows ending at ``ends``: on the first window
    at least ``every`` samples after the previous check, refitted (row_edf) unless the
    last refit's model still holds there (``_model_holds``), and held in between, so
    batch and streaming engines pick the same windows. ``prev`` is the state returned for
    the windows before these, or None. Returns (EDF (T x M; a read-only broadcast of one
    row when one row holds for all these windows), state)."""
    edf_now, model_now, end_now = (None, None, None) if prev is None else prev
    if len(ends) == 0:
        return np.zeros((0, len(m))), (edf_now, model_now, end_now)
    seg_start, seg_edf = [0], [edf_now]
    r = 0 if end_now is None else int(np.searchsorted(ends, end_now + every))
    while r < len(ends):
        end_now = int(ends[r])
        if model_now is None or not _model_holds(model_now, sums[r], counts[r], m):
            terms = _row_terms(sums[r], counts[r], m, n_samples)
            edf_now, model_now = _terms_edf(terms, m, n_samples, _avar(sums[r], counts[r]))[0], _model_curve(terms, m)
            seg_start.append(r)
            seg_edf.append(edf_now)
        r = int(np.searchsorted(ends, end_now + every))
    state = (edf_now, model_now, end_now)
    if seg_edf[0] is None:  # the first call: its first window is always refitted
        seg_start, seg_edf = seg_start[1:], seg_edf[1:]
    if len(seg_edf) == 1:  # one EDF row for every window: a read-only view (see adev_edf)
        return np.broadcast_to(np.asarray(seg_edf[0]), (len(ends), len(m))), state
    seg = np.searchsorted(np.array(seg_start), np.arange(len(ends)), side="right") - 1
    return np.array(seg_edf)[seg], state


@lru_cache(maxsize=256)
def _gapless_edf(alpha: bytes, m: bytes, n_samples: int) -> np.ndarray:
    """Gap-free EDF per tau for int64 ``alpha`` and ``m`` given as bytes (cached:
    streaming asks for the same ones block after block)."""
    return edf_full(np.frombuffer(alpha, np.int64), np.frombuffer(m, np.int64), n_samples)


def gapless_edf(alpha, m, n_samples: int) -> np.ndarray:
    """Gap-free EDF per tau, (1, M), for one noise-type row ``alpha`` (int, per tau m) of
    windows of ``n_samples``."""
    a = np.ascontiguousarray(np.broadcast_to(alpha, np.shape(m)), dtype=np.int64)
    return _gapless_edf(a.tobytes(), np.ascontiguousarray(m, dtype=np.int64).tobytes(), int(n_samples)).reshape(1, -1)


def adev_edf(sums, counts, m, n_samples: int, alpha=None, gapless=None) -> tuple[np.ndarray, np.ndarray]:
    """(adev_dph, edf) from sums of squared terms and valid-term counts (shape (..., M))
    of windows of ``n_samples``. The gap-free EDF per tau: Greenhall's for the noise type
    ``alpha`` (scalar, (M,) or (..., M)) when given, else ``gapless`` (rows over windows,
    piecewise constant: ``edf_rows``), else that of the noise mixture of a quick IEEE-952
    fit of each window (``row_edf``). The EDF is a read-only broadcast of one row when
    one row holds and no entry has a gap."""
    shape = np.shape(sums)
    nm = len(m)
    sums = np.asarray(sums, dtype=np.float64).reshape(-1, nm)
    counts = np.asarray(counts, dtype=np.int64).reshape(-1, nm)
    m = np.ascontiguousarray(m, dtype=np.int64)
    if alpha is None and gapless is None:
        gapless = np.concatenate([np.empty((0, nm))] + [row_edf(s, c, m, n_samples)
                                                      for s, c in zip(sums, counts, strict=True)])
    # the result array allocated here (a numba kernel returning a new array pays ~2 us to box it)
    adev = np.empty(sums.shape)
    # counts broadcast from one row (the streaming engine without gaps): the kernel reads that row
    one_row = counts[:1] if counts.strides[0] == 0 else counts
    n_gapped = window_stats.frame_stats(c_array(sums, np.float64), c_array(one_row, np.int64),
                                        n_samples - 2 * m + 1, adev)
    edf = window_edf(counts, m, n_samples, alpha, gapless, n_gapped)
    return adev.reshape(shape), edf.reshape(shape)


def window_edf(counts, m, n_samples: int, alpha=None, gapless=None, n_gapped: int | None = None) -> np.ndarray:
    """EDF per window x tau (T x M) of windows of ``n_samples`` with valid-term ``counts``
    (T x M; a broadcast of one row when all windows have the same): the gap-free EDF per
    tau (Greenhall's for the noise type ``alpha`` when given, else the rows ``gapless``,
    see :func:`adev_edf`), the effective EDF where an entry has fewer terms than a
    gap-free window. ``n_gapped``: the number of those entries when known
    (``window_stats.frame_stats`` counts them), else counted here."""
    nm = len(m)
    counts = np.asarray(counts, dtype=np.int64).reshape(-1, nm)
    m = np.ascontiguousarray(m, dtype=np.int64)
    shape = counts.shape
    if n_gapped is None:
        full = n_samples - 2 * m + 1
        if len(counts) and counts.strides[0] == 0:  # one row of counts for all windows
            n_gapped = int(np.count_nonzero(counts[0] != full)) * len(counts)
        else:
            n_gapped = int(np.count_nonzero(counts != full))
    if alpha is not None:
        rows = np.asarray(alpha, dtype=np.int64)
        edf_row = functools.partial(gapless_edf, m=m, n_samples=n_samples)
    else:
        rows = np.asarray(gapless, dtype=np.float64)
        edf_row = functools.partial(np.reshape, shape=(1, nm))
    if rows.ndim == 2 and (len(rows) == 1 or (len(rows) and rows.strides[0] == 0)):  # one row (edf_rows' view)
        rows = rows[0]
    if rows.ndim <= 1:  # one row for every window
        edf_runs = edf_row(rows)
        run = np.zeros(len(counts), dtype=np.int64)
    else:  # piecewise constant over windows: one EDF row per run
        rows = np.broadcast_to(rows, shape).reshape(-1, nm)
        new_run = np.ones(len(rows), dtype=bool)
        new_run[1:] = np.any(rows[1:] != rows[:-1], axis=1)
        run = np.cumsum(new_run) - 1
        edf_runs = np.concatenate([np.empty((0, nm)), *(edf_row(a) for a in rows[new_run])])
    return gapped_edf(edf_runs, run, counts, n_gapped, m, n_samples)


def statistics(sums, counts, m, n_samples: int, alpha=None, confidence: float = CONFIDENCE, gapless=None):
    """(adev_dph, lo_dph, hi_dph, edf) of :func:`adev_edf`, with the two-sided
    ``confidence`` chi-square interval."""
    adev, edf = adev_edf(sums, counts, m, n_samples, alpha, gapless)
    lo, hi = chi2_bounds(adev, edf, confidence)
    return adev, lo, hi, edf


def record_statistics(y: np.ndarray, ok: np.ndarray, sample_rate_hz: float, sums, counts, m, n_samples: int,
                      confidence: float = CONFIDENCE, exact_shape: bool = True):
    """(adev_dph, lo_dph, hi_dph, edf, ramp_k) of a whole record (rate ``y`` in deg/h at
    ``sample_rate_hz``, valid ``ok``; one window's ``sums``, ``counts``): the EDF of the quick IEEE-952 fit's mixture
    under ``record_mixture``'s rules (a ramp deterministic only where the fit rejects R = 0
    at ``record_mixture.DETERMINISTIC_Z`` and does not identify K, K then from the detrended
    record), capped below a low-pass's peak as
    ``row_edf``; with ``exact_shape``, at the gap-free taus where few independent terms
    remain (``shape.shape_applies``: M / m <= 16) the exact shape of that mixture's Allan
    variance instead of chi-square's (docs/davar.md, "Calibration"). ``ramp_k``: the
    detrended record's A_K ((deg/h)^2 s^-1) where the ramp counts as deterministic, else NaN
    (``AdevResult.ramp_k``)."""
    avar = _avar(sums, counts)
    terms = _row_terms(sums, counts, m, n_samples)
    tau_s = np.asarray(m) / sample_rate_hz
    deterministic = record_mixture.deterministic_ramp(record_mixture.record_fit(tau_s, avar, m, counts, n_samples))
    k_detr = _detrended_k(y, ok, m, n_samples) if deterministic else None
    fractions = record_mixture.fractions(terms, deterministic, m, k_detr)
    gapless = _capped_below_peak(record_mixture.edf_row(fractions, m, n_samples), avar)
    adev, edf = adev_edf(sums, counts, m, n_samples, None, gapless)
    lo, hi = chi2_bounds(adev, edf, confidence)
    if exact_shape:
        lo, hi = _shaped_bounds(fractions, adev, lo, hi, edf, counts, m, n_samples, confidence)
    ramp_k = k_detr * sample_rate_hz if k_detr is not None else np.nan  # tau in sample periods -> in s
    return adev, lo, hi, edf, ramp_k


def _detrended_k(y: np.ndarray, ok: np.ndarray, m, n_samples: int) -> float | None:
    """``record_mixture.detrended_k`` of the record ``y`` with the least-squares line
    through its valid finite samples removed (None: fewer than 3)."""
    use = ok & np.isfinite(y)
    if np.count_nonzero(use) < 3:
        return None
    t = np.arange(len(y), dtype=np.float64)
    slope, offset = np.polyfit(t[use], y[use], 1)
    yd = c_array(np.where(np.isfinite(y), y - (slope * t + offset), y), np.float64)
    hi_, lo_, bad = kernels.prefix_sums_dd(yd, ok, reference_level(yd, ok))
    sums, counts = kernels.window_sums(hi_, lo_, bad, m, np.zeros(1, np.int64), n_samples)
    return record_mixture.detrended_k(_avar(sums[0], counts[0]), m, counts[0], n_samples)


def _shaped_bounds(fractions, adev, lo, hi, edf, counts, m, n_samples: int, confidence: float):
    """``lo``, ``hi`` with the exact-shape interval (``shape.shape_factors``) of the
    mixture ``fractions`` (taus x classes) at the gap-free taus where it applies and
    chi-square gives an interval (EDF >= confidence.MIN_EDF)."""
    m = np.asarray(m, dtype=np.int64)
    use = (shape_applies(m, n_samples) & (np.asarray(counts) == n_samples - 2 * m + 1) & np.isfinite(lo)
           & np.isfinite(hi))
    if not use.any():
        return lo, hi
    f_lo, f_hi = shape_factors(fractions[use], m[use], n_samples, np.asarray(edf)[use], confidence)
    lo, hi = np.array(lo, dtype=np.float64), np.array(hi, dtype=np.float64)
    ok = np.isfinite(f_lo) & np.isfinite(f_hi)  # else chi-square's
    at = np.flatnonzero(use)[ok]
    lo[at], hi[at] = adev[at] * f_lo[ok], adev[at] * f_hi[ok]
    return lo, hi


def gapped_edf(edf_runs, run, counts, n_gapped: int, m, n_samples: int) -> np.ndarray:
    """EDF per window x tau (windows ``run``'s rows of the gap-free ``edf_runs``; a
    read-only broadcast when one row holds for all and no entry has a gap) after
    ``window_stats.frame_stats``: its ``n_gapped`` entries with fewer terms than a gap-free
    window get their effective EDF."""
    if n_gapped == 0 and len(edf_runs) == 1:
        return np.broadcast_to(edf_runs[0], (len(run), len(m)))
    edf = edf_runs[run]
    if n_gapped:
        counts = np.broadcast_to(counts, edf.shape)
        gapped = counts != n_samples - 2 * np.asarray(m) + 1
        edf[gapped] = edf_effective(edf[gapped], np.broadcast_to(m, edf.shape)[gapped], n_samples, counts[gapped])
    return edf


def oadev(rate_dph, sample_rate_hz: float, taus="octave", valid=None, confidence: float = CONFIDENCE,
          alpha=None, exact_shape: bool = True) -> AdevResult:
    """Overlapping Allan deviation (deg/h) of a rate record ``rate_dph`` (deg/h) sampled at
    ``sample_rate_hz`` (Hz). ``taus``: see :func:`fogmon.davar.taus.tau_grid`. ``valid``: optional
    mask; NaN samples are invalid too. Bounds at ``confidence``: with the EDF of the
    noise mixture a quick IEEE-952 fit predicts (:func:`record_statistics`; with
    ``exact_shape`` the exact shape of its Allan variance at the taus with few
    independent terms, else chi-square), or chi-square with Greenhall's EDF for the
    noise type ``alpha`` when given (Stable32's)."""
    y, ok = _prepare(rate_dph, valid)
    n = len(y)
    m = tau_grid(sample_rate_hz, n, taus)
    hi_, lo_, bad = kernels.prefix_sums_dd(y, ok, reference_level(y, ok))
    sums, counts = kernels.window_sums(hi_, lo_, bad, m, np.zeros(1, np.int64), n)
    ramp_k = np.nan
    if alpha is None:
        adev, lo, hi, edf, ramp_k = record_statistics(y, ok, sample_rate_hz, sums[0], counts[0], m, n, confidence,
                                                      exact_shape)
    else:
        adev, lo, hi, edf = statistics(sums[0], counts[0], m, n, alpha, confidence)
    return AdevResult(m / sample_rate_hz, m, adev, lo, hi, edf, counts[0], float(sample_rate_hz), n, confidence,
                      float(ramp_k))


def dadev(rate_dph, sample_rate_hz: float, window_s: float, hop_s: float | None = None, taus="octave",
          valid=None, confidence: float = CONFIDENCE, t0_s: float = 0.0, alpha=None) -> DadevResult:
    """Dynamic Allan deviation: overlapping ADEV (deg/h) of every window of ``window_s`` s,
    windows starting every ``hop_s`` s (default window_s / 4) from the first sample at
    time ``t0_s`` (s); only complete windows. Taus limited to window / 4. Without
    ``alpha`` the EDF's quick fit is refitted every max(hop, window / 4) samples (see
    :func:`edf_rows`)."""
    y, ok = _prepare(rate_dph, valid)
    w = _samples(window_s, sample_rate_hz, "window_s")
    hop = _samples(window_s / 4.0 if hop_s is None else hop_s, sample_rate_hz, "hop_s")
    m = tau_grid(sample_rate_hz, w, taus)
    starts = np.arange(0, len(y) - w + 1, hop, dtype=np.int64)
    hi_, lo_, bad = kernels.prefix_sums_dd(y, ok, reference_level(y, ok))
    sums, counts = kernels.window_sums(hi_, lo_, bad, m, starts, w)
    end = starts + w - 1
    gapless = None if alpha is not None else edf_rows(sums, counts, end, m, w, max(hop, w // 4))[0]
    adev, edf = adev_edf(sums, counts, m, w, alpha, gapless)
    return DadevResult(t0_s + (starts + (w - 1) / 2.0) / sample_rate_hz, end, m / sample_rate_hz, m, adev, edf, counts,
                       float(sample_rate_hz), w / sample_rate_hz, hop / sample_rate_hz, confidence)
