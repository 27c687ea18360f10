"""Chi-square confidence intervals of the overlapping Allan deviation.

sigma_hat^2 ~ sigma^2 chi2_nu / nu with nu from Greenhall & Riley's EDF algorithm
(Greenhall 2004, overlapping ADEV: d = 2, F = S = m; the cases of
``allantools.ci.edf_greenhall``, which tests/test_davar_theory_confidence.py checks it against,
evaluated here so that a run needs neither allantools nor scipy.stats). The noise type alpha
(S_y ~ f^alpha) per tau comes from the dominant IEEE-952 term (``ALPHA_OF_TERM``) or from
the caller. When gaps remove terms, nu is scaled by the fraction of terms still valid.
For the noise fit: the EDF of a noise mixture (``edf_mixture``) and the exact covariance
of Allan variance estimates across taus (``avar_relative_covariance``).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from fogmon.davar.result import CONFIDENCE

ALPHA_OF_TERM = np.array([2, 0, -1, -2, -2])
"""Power-law exponent alpha of each IEEE-952 term Q, N, B, K, R (R treated as random walk)."""


def edf_full(alpha, m, n_samples: int) -> np.ndarray:
    """Greenhall EDF of an overlapping ADEV with averaging factors ``m`` over
    ``n_samples`` gap-free rate samples for noise type(s) ``alpha`` (scalar or per m).
    NaN where 2 m > n_samples. Cached per (alpha, m, n_samples)."""
    m = np.atleast_1d(np.asarray(m, dtype=np.int64))
    alpha = np.broadcast_to(np.asarray(alpha, dtype=np.int64), m.shape)
    return np.array([_edf_greenhall(int(a), int(k), int(n_samples)) if 2 * k <= n_samples else np.nan
                     for a, k in zip(alpha, m, strict=True)])


def edf_effective(edf_gapless: np.ndarray, m: np.ndarray, n_samples: int, n_terms: np.ndarray) -> np.ndarray:
    """Scale gap-free EDF (over m, last axis) by the fraction of overlapping terms that
    are valid, ``n_terms / (n_samples - 2 m + 1)``; NaN where no term is valid."""
    n_terms = np.asarray(n_terms)
    full = np.maximum(n_samples - 2 * np.asarray(m) + 1, 1)
    with np.errstate(invalid="ignore"):
        return np.where(n_terms > 0, edf_gapless * (n_terms / full), np.nan)


MIX_ALPHAS = (2, 0, -1, -2)
"""Noise types of the mixture EDF (``edf_mixture``): white angle, white rate, flicker, random walk."""
_GRID_PER_M = 256  # above this m: F = inf and at most 6 x this many lags (Riemann sum)


def _sw(t: np.ndarray, alpha: int) -> np.ndarray:
    """Greenhall (2004) eq. 7 for noise type ``alpha`` (2 .. -4) at lags ``t``, up to a sign
    per alpha: -|t| (alpha 2), |t|^(3 - alpha) (even alpha), t^(3 - alpha) ln|t| (odd)."""
    a = np.abs(t)
    if alpha == 2:
        return -a
    if alpha % 2 == 0:
        return a ** (3 - alpha)
    with np.errstate(divide="ignore", invalid="ignore"):
        return t ** (3 - alpha) * np.where(a > 0, np.log(np.where(a > 0, a, 1.0)), 0.0)


def _sz(t: np.ndarray, f: float, alpha: int) -> np.ndarray:
    """Greenhall eqs. 8-9 for the Allan variance (d = 2): autocovariance (up to a constant)
    of the Allan terms at lag t (units of m samples), filter factor ``f`` (m, or inf)."""
    def sx(u):
        if np.isinf(f):
            return _sw(u, alpha + 2)
        return f**2 * (2.0 * _sw(u, alpha) - _sw(u - 1.0 / f, alpha) - _sw(u + 1.0 / f, alpha))
    return 6.0 * sx(t) - 4.0 * (sx(t - 1.0) + sx(t + 1.0)) + sx(t - 2.0) + sx(t + 2.0)


_J_MAX = 100  # Greenhall's limit of the BasicSum's lags
_TABLE2_D2 = {2: (35.0 / 18.0, 1.0), 1: (790.0, 410.0), 0: (2.0 / 3.0, 1.0 / 3.0), -1: (0.852, 0.375),
              -2: (1.079, 0.368)}
"""Greenhall's table 2 (a0, a1) for d = 2 per alpha: 1 / EDF ~ (a0 - a1 / r) / r for long records."""
_TABLE3_D2 = (15.23, 12.0)  # Greenhall's table 3 (b0, b1) for d = 2, alpha = 1


def _basic_sum(j: int, big_m: float, s: float, f: float, alpha: int) -> float:
    """Greenhall's BasicSum: sz(0)^2 + (1 - J/M) sz(J/S)^2 + 2 sum_{0<j<J} (1 - j/M) sz(j/S)^2."""
    lag = np.arange(1, j, dtype=np.float64)
    inner = 2.0 * (1.0 - lag / big_m) * _sz(lag / s, f, alpha) ** 2
    ends = _sz(np.array([0.0, j / s]), f, alpha) ** 2
    return float(ends[0] + (1.0 - j / big_m) * ends[1] + inner.sum())


@lru_cache(maxsize=1 << 16)
def _edf_greenhall(alpha: int, m: int, n_samples: int) -> float:
    """Greenhall's EDF of the overlapping Allan variance (d = 2, F = S = m) of
    ``n_samples`` rate samples (n + 1 phase points, so M = n - 2m + 1 terms)."""
    if not -2 <= alpha <= 2:
        raise ValueError(f"noise type alpha {alpha} outside 2 .. -2")
    big_m = float(n_samples - 2 * m + 1)
    j = min(big_m, 3.0 * m)
    r = big_m / m
    if alpha == 2:  # case 4
        if np.ceil(r) <= 2:
            raise ValueError(f"no Greenhall EDF for alpha 2 with {big_m:g} terms of m = {m}")
        return 1.0 / ((70.0 / 36.0 - 1.0 / r) / big_m)  # a0 = C(8, 4) / C(4, 2)^2, a1 = d / 2
    f = float(m)
    if alpha == 1:  # case 3
        if j <= _J_MAX:
            return 1.0 / (_basic_sum(int(j), big_m, m, f, 1) / (_sz(np.zeros(1), f, 1)[0] ** 2 * big_m))
        b = (_TABLE3_D2[0] + _TABLE3_D2[1] * np.log(m)) ** 2
        if r > 3:
            a0, a1 = _TABLE2_D2[1]
            return 1.0 / ((a0 - a1 / r) / (b * r))
        mp = _J_MAX / r
        return 1.0 / (_basic_sum(_J_MAX, _J_MAX, mp, mp, 1) / (b * _J_MAX))
    if j <= _J_MAX:  # case 2: alpha <= 0
        f = f if 3 * m <= _J_MAX else np.inf
        return 1.0 / (_basic_sum(int(j), big_m, m, f, alpha) / (_sz(np.zeros(1), f, alpha)[0] ** 2 * big_m))
    if r > 3:
        a0, a1 = _TABLE2_D2[alpha]
        return 1.0 / ((a0 - a1 / r) / r)
    return 1.0 / (_basic_sum(_J_MAX, _J_MAX, _J_MAX / r, np.inf, alpha)
                  / (_sz(np.zeros(1), np.inf, alpha)[0] ** 2 * _J_MAX))


def _discrete_rho(m: int, alpha: int, j: np.ndarray) -> np.ndarray:
    """Exact autocorrelation at integer lags ``j`` of the Allan terms of averaging factor m
    of rate samples that are white (alpha 0) or a random walk of white steps (alpha -2):
    the terms are a finite filter of white noise (Greenhall's F = m form is a
    continuous-time approximation, ~9 % low in EDF for white rate noise at m = 8)."""
    h = np.concatenate([-np.ones(m), np.ones(m)])
    g = h if alpha == 0 else np.cumsum(h[::-1])[::-1][1:]  # random walk: tail sums of h
    acf = np.correlate(g, g, "full")  # lags -(len(g)-1) .. len(g)-1
    mid = len(g) - 1
    ji = np.abs(j).astype(np.int64)
    return np.where(ji <= mid, acf[np.minimum(ji, mid) + mid], 0.0) / acf[mid]


@lru_cache(maxsize=1 << 12)
def _mixture_matrix(m: int, n_samples: int) -> np.ndarray:
    """C[k, l] = sum over lags j of (1 - |j|/M) rho_k(j) rho_l(j), rho the normalized
    autocorrelation of the overlapping Allan terms of noise types MIX_ALPHAS (M = n - 2m + 1
    terms, lags up to 3m as in Greenhall's BasicSum): the relative variance of the Allan
    variance of a mixture with variance fractions f is 2 f'Cf / M."""
    big_m = n_samples - 2 * m + 1
    lag_max = min(3 * m, big_m - 1)
    f = float(m) if m <= _GRID_PER_M else np.inf  # F = inf: Greenhall's large-m limit
    if lag_max <= 3 * _GRID_PER_M:
        j, step = np.arange(-lag_max, lag_max + 1, dtype=np.float64), 1.0
    else:  # smooth ACFs: Riemann sum over 6 _GRID_PER_M + 1 lags
        j = np.linspace(-lag_max, lag_max, 6 * _GRID_PER_M + 1)
        step = j[1] - j[0]
    t = j / m
    w = step * np.maximum(1.0 - np.abs(j) / big_m, 0.0)
    spikes = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])  # white angle noise: Allan terms m, 2m apart only

    def rho_of(alpha, tt):
        if np.isfinite(f) and alpha in (0, -2):
            return _discrete_rho(m, alpha, np.round(tt * m))
        return _sz(tt, f, alpha) / _sz(np.zeros(1), f, alpha)
    rho = [rho_of(a, t) for a in MIX_ALPHAS[1:]]
    w_s = np.maximum(1.0 - np.abs(spikes) * m / big_m, 0.0)
    rho_q = np.array([1.0, -4.0, 6.0, -4.0, 1.0]) / 6.0
    rho_q_at = [rho_of(a, spikes) for a in MIX_ALPHAS[1:]]
    c = np.empty((4, 4))
    c[0, 0] = np.sum(w_s * rho_q**2)
    for k in range(3):
        c[0, k + 1] = c[k + 1, 0] = np.sum(w_s * rho_q * rho_q_at[k])
        for k2 in range(k, 3):
            c[k + 1, k2 + 1] = c[k2 + 1, k + 1] = np.sum(w * rho[k] * rho[k2])
    return c


def edf_mixture(fractions: np.ndarray, m, n_samples: int) -> np.ndarray:
    """EDF of overlapping Allan variances over ``n_samples`` gap-free rate samples whose
    noise is a mixture: ``fractions`` (taus x 4) of the Allan variance at each m from
    white angle, white rate, flicker and random-walk rate noise (MIX_ALPHAS). Exact for
    Gaussian noise (the Allan terms' autocorrelation is the fraction-weighted sum of the
    types'): exact discrete-time autocorrelations for white angle, white rate and random
    walk up to m = 256, Greenhall's (F = inf) beyond and for flicker. NaN where 2 m > n."""
    m = np.atleast_1d(np.asarray(m, dtype=np.int64))
    return edf_mixture_from(fractions, mixture_matrices(m, n_samples), n_samples - 2 * m + 1)


def edf_mixture_from(fractions: np.ndarray, matrices: np.ndarray, n_terms_full: np.ndarray) -> np.ndarray:
    """``edf_mixture`` from precomputed ``mixture_matrices`` and gap-free term counts
    n - 2m + 1 (for repeated evaluation inside a fit)."""
    f = np.asarray(fractions, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return n_terms_full / np.einsum("ti,tij,tj->t", f, matrices, f)


def mixture_matrices(m, n_samples: int) -> np.ndarray:
    """The (len(m), 4, 4) matrices of ``edf_mixture`` (NaN where 2 m > n_samples)."""
    return _mixture_matrices(tuple(int(k) for k in np.atleast_1d(m)), int(n_samples))


@lru_cache(maxsize=256)
def _mixture_matrices(m: tuple, n_samples: int) -> np.ndarray:
    return np.array([_mixture_matrix(k, n_samples) if 2 * k <= n_samples else np.full((4, 4), np.nan)
                     for k in m]).reshape(len(m), 4, 4)


_SECOND_DIFF = np.array([1.0, -2.0, 1.0])
"""An Allan term of factor m is (X[j + 2m] - 2 X[j + m] + X[j]) / m, X = cumsum(rate)."""
_EXACT_SEGMENT = 48  # lag segments up to this long are summed term by term
_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(12)


def _phase_acv(t: np.ndarray, alpha: int) -> np.ndarray:
    """Generalized autocovariance (up to a constant) of the phase X = cumsum(rate) at
    lag ``t`` (samples) for rate noise type ``alpha`` 0, -1, -2: exact at integer lags
    for discrete white rate (-|t|) and random-walk rate ((|t|^3 - |t|)) noise,
    Greenhall's continuous t^2 ln|t| for flicker."""
    a = np.abs(t)
    if alpha == 0:
        return -a
    if alpha == -2:
        return a**3 - a
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a > 0, t * t * np.log(np.where(a > 0, a, 1.0)), 0.0)


def _term_xcov_raw(lag: np.ndarray, ma: np.ndarray, mb: np.ndarray, alpha: int) -> np.ndarray:
    """Covariance (up to a constant) of the Allan term of factor ``ma`` at j with that of
    ``mb`` at j + lag (arrays of one shape)."""
    i, j = np.divmod(np.arange(9), 3)
    off = j * np.asarray(mb)[..., None] - i * np.asarray(ma)[..., None]
    return (_SECOND_DIFF[i] * _SECOND_DIFF[j] * _phase_acv(np.asarray(lag)[..., None] + off, alpha)).sum(-1)


def _pair_count(lag: np.ndarray, ma_terms, mb_terms) -> np.ndarray:
    """Number of term pairs (j, j + lag) with 0 <= j < ma_terms and 0 <= j + lag < mb_terms."""
    return np.maximum(np.minimum(ma_terms, mb_terms - lag) - np.maximum(0, -lag), 0).astype(np.float64)


def _pair_lags(ma: int, mb: int, n_a: int, n_b: int) -> tuple[np.ndarray, np.ndarray]:
    """Lags (float) and quadrature weights of the sum over lags of ``covariance_matrices``
    for factors ma, mb with n_a, n_b terms: the terms' overlap plus 4 max(ma, mb) for
    flicker's tail, every lag on segments up to _EXACT_SEGMENT between the kinks
    p ma - q mb, the kink and 12-point Gauss-Legendre on longer ones."""
    kinks = (np.arange(3)[:, None] * ma - np.arange(3)[None, :] * mb).ravel()
    lo = max(kinks.min() - 4 * max(ma, mb), -(n_a - 1))
    hi = min(kinks.max() + 4 * max(ma, mb), n_b - 1) + 1
    knots = np.unique(np.clip(np.concatenate([kinks, [lo, hi, 0, n_b - n_a]]), lo, hi))
    lags, wts = [], []
    for a, b in zip(knots[:-1], knots[1:], strict=True):
        if b - a <= _EXACT_SEGMENT:
            lags.append(np.arange(a, b, dtype=np.float64))
            wts.append(np.ones(b - a))
        else:  # the kink lag itself, then the smooth lags a + 1 .. b - 1 as an integral
            half = 0.5 * (b - a - 1)
            lags += [np.array([float(a)]), half * _GAUSS_X + 0.5 * (a + b)]
            wts += [np.ones(1), half * _GAUSS_W]
    return np.concatenate(lags), np.concatenate(wts)


def covariance_matrices(m, n_samples: int) -> np.ndarray:
    """The (len(m), len(m), 4, 4) matrices C[k, l] = sum over lags of N(lag) rho_k(lag)
    rho_l(lag) of every pair of averaging factors ``m`` (ma, mb) over ``n_samples``
    gap-free rate samples (all 2 m <= n; cached per grid): for noise types MIX_ALPHAS,
    rho the cross-correlation of the two factors' Allan terms, N the number of term
    pairs at that lag. The relative covariance of the two Allan variances of a mixture is
    2 g'Cg / (M_a M_b), g_k = sqrt(f_a,k f_b,k). Lags as ``_pair_lags`` (exact for the
    white and random-walk polynomials); white angle noise correlates terms only at the
    kink lags. All pairs are evaluated in one vectorised pass."""
    return _covariance_matrices(tuple(int(k) for k in np.atleast_1d(m)), int(n_samples))


_PAIR_CACHE: dict[tuple[int, int, int], np.ndarray] = {}
_PAIR_CACHE_MAX = 1 << 14  # pairs kept (grids whose usable taus differ share their pairs)


@lru_cache(maxsize=64)
def _covariance_matrices(m: tuple, n_samples: int) -> np.ndarray:
    ia, ib = np.triu_indices(len(m))
    keys = [(m[a], m[b], n_samples) for a, b in zip(ia, ib, strict=True)]
    todo = sorted({k for k in keys if k not in _PAIR_CACHE})
    if todo:
        if len(_PAIR_CACHE) + len(todo) > _PAIR_CACHE_MAX:
            _PAIR_CACHE.clear()
        ma, mb = (np.array([k[i] for k in todo], dtype=np.int64) for i in (0, 1))
        _PAIR_CACHE.update(zip(todo, _cross_matrices(ma, mb, n_samples), strict=True))
    c = np.array([_PAIR_CACHE[k] for k in keys])
    out = np.empty((len(m), len(m), 4, 4))
    out[ia, ib] = c
    out[ib, ia] = c
    return out


def _cross_matrices(ma: np.ndarray, mb: np.ndarray, n_samples: int) -> np.ndarray:
    """``covariance_matrices``' (4, 4) matrix of each pair of factors (ma[i], mb[i])."""
    n_a, n_b = n_samples - 2 * ma + 1, n_samples - 2 * mb + 1
    parts = [_pair_lags(int(a), int(b), int(na), int(nb)) for a, b, na, nb in zip(ma, mb, n_a, n_b, strict=True)]
    pair = np.repeat(np.arange(len(ma)), [len(lg) for lg, _ in parts])
    lag = np.concatenate([lg for lg, _ in parts])
    w = np.concatenate([wt for _, wt in parts]) * _pair_count(lag, n_a[pair], n_b[pair])
    # white angle noise: X is white, so terms correlate only at the kink lags p ma - q mb
    # (each distinct kink once, its weights summed)
    p, q = np.divmod(np.arange(9), 3)
    kinks = p * ma[:, None] - q * mb[:, None]
    k_pair, k_lag, inv = _distinct_rows(np.repeat(np.arange(len(ma)), 9), kinks.ravel())
    rho_q = np.bincount(inv, weights=np.tile(_SECOND_DIFF[p] * _SECOND_DIFF[q], len(ma)),
                        minlength=len(k_lag)) / 6.0
    w_q = _pair_count(k_lag, n_a[k_pair], n_b[k_pair])
    c = np.empty((len(ma), 4, 4))
    c[:, 0, 0] = np.bincount(k_pair, weights=w_q * rho_q**2, minlength=len(ma))
    rho = []
    for k, al in enumerate(MIX_ALPHAS[1:]):
        scale = _term_sd(ma, al) * _term_sd(mb, al)
        rho.append(_term_xcov_raw(lag, ma[pair], mb[pair], al) / scale[pair])
        rho_at_kinks = _term_xcov_raw(k_lag, ma[k_pair], mb[k_pair], al) / scale[k_pair]
        c[:, 0, k + 1] = c[:, k + 1, 0] = np.bincount(k_pair, weights=w_q * rho_q * rho_at_kinks, minlength=len(ma))
    for k in range(3):
        for k2 in range(k, 3):
            c[:, k + 1, k2 + 1] = c[:, k2 + 1, k + 1] = np.bincount(pair, weights=w * rho[k] * rho[k2],
                                                                    minlength=len(ma))
    return c


def _term_sd(m: np.ndarray, alpha: int) -> np.ndarray:
    """Standard deviation (the constant of ``_term_xcov_raw``) of an Allan term of each factor m."""
    return np.sqrt(_term_xcov_raw(np.zeros(len(m)), m, m, alpha))


def _distinct_rows(group: np.ndarray, value: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct (group, value) pairs (group, value, each input's index among them)."""
    key, inv = np.unique(np.stack([group, value], axis=1), axis=0, return_inverse=True)
    return key[:, 0], key[:, 1].astype(np.float64), inv.ravel()


def avar_relative_covariance(fractions: np.ndarray, matrices: np.ndarray, n_terms_full: np.ndarray) -> np.ndarray:
    """Covariance of overlapping Allan variance estimates across taus, relative to the
    product of their expectations (T x T; diagonal 2 / EDF), for Gaussian noise whose
    Allan variance at each tau is split by ``fractions`` (T x 4, MIX_ALPHAS) over white
    angle, white rate, flicker and random-walk rate noise: exact (it is a quadratic form
    in the data: cov = 2 tr(A S B S)), from ``covariance_matrices`` and the gap-free term
    counts n - 2 m + 1."""
    f = np.asarray(fractions, dtype=np.float64)
    g = np.sqrt(f[:, None, :] * f[None, :, :])
    return 2.0 * np.einsum("abk,abkl,abl->ab", g, matrices, g) / np.outer(n_terms_full, n_terms_full)


@lru_cache(maxsize=64)
def _quantiles(confidence: float) -> tuple[float, float]:
    lo = min(abs(confidence), abs(1.0 - confidence)) / 2.0
    return lo, 1.0 - lo


def chi2_bounds(adev: np.ndarray, edf: np.ndarray, confidence: float = CONFIDENCE) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided ``confidence`` interval (lo, hi) of a deviation ``adev`` (any unit) with
    ``edf`` degrees of freedom (NIST SP1065 eq. 45). chi2 quantiles are evaluated once
    per distinct EDF value."""
    adev = np.asarray(adev, dtype=np.float64)
    edf = np.broadcast_to(np.asarray(edf, dtype=np.float64), adev.shape)
    from scipy.special import gammaincinv  # imported here: scipy costs start-up time

    q_lo, q_hi = _quantiles(float(confidence))
    ok = np.isfinite(edf) & (edf > 0)
    f_lo = np.full(adev.shape, np.nan)
    f_hi = np.full(adev.shape, np.nan)
    if ok.any():
        u, inv = np.unique(edf[ok], return_inverse=True)
        with np.errstate(divide="ignore", over="ignore"):  # tiny EDF: hi is +inf
            # the chi2 quantile with u degrees of freedom at q is 2 gammaincinv(u / 2, q)
            f_lo[ok] = np.sqrt(u / (2.0 * gammaincinv(u / 2.0, q_hi)))[inv]
            f_hi[ok] = np.sqrt(u / (2.0 * gammaincinv(u / 2.0, q_lo)))[inv]
    return adev * f_lo, adev * f_hi
