"""Chi-square confidence intervals of the overlapping Allan deviation.

sigma_hat^2 ~ sigma^2 chi2_nu / nu with nu the EDF of the noise mixture the fitted
IEEE-952 terms predict at each tau (``edf_mixture``: white angle, white rate, flicker,
random walk and a deterministic rate ramp), or for a noise type alpha (S_y ~ f^alpha) the
caller names, Greenhall & Riley's EDF (Greenhall 2004, overlapping ADEV: d = 2, F = S = m;
the cases of ``allantools.ci.edf_greenhall``, which tests/davar/test_theory_confidence.py
checks it against, evaluated here so that a run needs neither allantools nor scipy.stats).
When gaps remove terms, nu is scaled by the fraction of terms still valid. For the noise
fit: the exact covariance of Allan variance estimates across taus
(``avar_relative_covariance``).
"""
from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import numpy as np

from fogmon.davar.theory import POWERS

#: Two-sided confidence of every interval fogmon reports (1 sigma of a normal).
CONFIDENCE = 0.683


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
RAMP = len(MIX_ALPHAS)
"""Index of the rate ramp (IEEE-952 R) among the mixture's classes, after the noise types:
a deterministic ramp adds the same constant c to every Allan term, so its own part c^2 / 2
of the Allan variance has no sampling variance; it only scales the mean of the noise's
terms, c x mean(e), whose variance the matrices carry in the ramp's row (``mixture_matrices``)."""
N_CLASSES = RAMP + 1
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


def _sz(t: np.ndarray, f: float | np.ndarray, alpha: int) -> np.ndarray:
    """Greenhall eqs. 8-9 for the Allan variance (d = 2): autocovariance (up to a constant)
    of the Allan terms at lag t (units of m samples), filter factor ``f`` (m, also one per
    lag, or inf)."""
    def sx(u):
        if np.isscalar(f) and np.isinf(f):
            return _sw(u, alpha + 2)
        return f**2 * (2.0 * _sw(u, alpha) - _sw(u - 1.0 / f, alpha) - _sw(u + 1.0 / f, alpha))
    return 6.0 * sx(t) - 4.0 * (sx(t - 1.0) + sx(t + 1.0)) + sx(t - 2.0) + sx(t + 2.0)


_J_MAX = 100  # Greenhall's limit of the BasicSum's lags
_TABLE2_D2 = {2: (35.0 / 18.0, 1.0), 1: (790.0, 410.0), 0: (2.0 / 3.0, 1.0 / 3.0), -1: (0.852, 0.375),
              -2: (1.079, 0.368)}
"""Greenhall's table 2 (a0, a1) for d = 2 per alpha: 1 / EDF ~ (a0 - a1 / r) / r for long records."""
_TABLE3_D2 = (15.23, 12.0)  # Greenhall's table 3 (b0, b1) for d = 2, alpha = 1


def _basic_sum(j: int, big_m: float, s: float, f: float, alpha: int) -> tuple[float, float]:
    """Greenhall's BasicSum sz(0)^2 + (1 - J/M) sz(J/S)^2 + 2 sum_{0<j<J} (1 - j/M) sz(j/S)^2,
    and sz(0)^2 (sz evaluated once at all the lags)."""
    lag = np.arange(1, j, dtype=np.float64)
    sz2 = _sz(np.r_[0.0, lag / s, j / s], f, alpha) ** 2
    inner = 2.0 * (1.0 - lag / big_m) * sz2[1:-1]
    return float(sz2[0] + (1.0 - j / big_m) * sz2[-1] + inner.sum()), float(sz2[0])


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
            basic, sz0 = _basic_sum(int(j), big_m, m, f, 1)
            return 1.0 / (basic / (sz0 * big_m))
        b = (_TABLE3_D2[0] + _TABLE3_D2[1] * np.log(m)) ** 2
        if r > 3:
            a0, a1 = _TABLE2_D2[1]
            return 1.0 / ((a0 - a1 / r) / (b * r))
        mp = _J_MAX / r
        return 1.0 / (_basic_sum(_J_MAX, _J_MAX, mp, mp, 1)[0] / (b * _J_MAX))
    if j <= _J_MAX:  # case 2: alpha <= 0
        f = f if 3 * m <= _J_MAX else np.inf
        basic, sz0 = _basic_sum(int(j), big_m, m, f, alpha)
        return 1.0 / (basic / (sz0 * big_m))
    if r > 3:
        a0, a1 = _TABLE2_D2[alpha]
        return 1.0 / ((a0 - a1 / r) / r)
    basic, sz0 = _basic_sum(_J_MAX, _J_MAX, _J_MAX / r, np.inf, alpha)
    return 1.0 / (basic / (sz0 * _J_MAX))


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


_SPIKES = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
"""Lags (units of m) at which white angle noise correlates Allan terms: m, 2m apart only."""
_RHO_Q = np.array([1.0, -4.0, 6.0, -4.0, 1.0]) / 6.0  # white angle noise's autocorrelation there


def _mixture_rows(m: np.ndarray, n_samples: int) -> np.ndarray:
    """``mixture_matrices`` of factors ``m`` (all 2 m <= n_samples): C[k, l] = sum over lags
    j of (1 - |j|/M) rho_k(j) rho_l(j), rho the normalized autocorrelation of the
    overlapping Allan terms of noise types MIX_ALPHAS (M = n - 2m + 1 terms, lags up to 3m
    as in Greenhall's BasicSum), and in the ramp's row C[RAMP, k] = sum over lags of
    (1 - |j|/M) rho_k(j) (M var(mean of the terms) / var(term)), C[RAMP, RAMP] = 0: the
    relative variance of the Allan variance of a mixture with variance fractions f
    (ramp included) is 2 f'Cf / M (c^2 var(mean e) = 2 f_R 2 sum_k f_k C[RAMP, k] / M
    relative to the variance squared). Every lag up to 3 _GRID_PER_M, beyond a
    Riemann sum over 6 _GRID_PER_M + 1 lags (smooth ACFs). The lags of all m (each m's
    followed by its _SPIKES) are evaluated together (``_mixture_rho``)."""
    t, w, q = [], [], []
    for k, big_m in zip(m, n_samples - 2 * m + 1, strict=True):
        lag_max = min(3 * k, big_m - 1)
        if lag_max <= 3 * _GRID_PER_M:
            j, step = np.arange(-lag_max, lag_max + 1, dtype=np.float64), 1.0
        else:
            j = np.linspace(-lag_max, lag_max, 6 * _GRID_PER_M + 1)
            step = j[1] - j[0]
        t += [j / k, _SPIKES]
        w += [step * np.maximum(1.0 - np.abs(j) / big_m, 0.0), np.maximum(1.0 - np.abs(_SPIKES) * k / big_m, 0.0)]
        q += [np.zeros(len(j)), _RHO_Q]
    size = np.array([len(x) for x in t])
    start = np.r_[0, np.cumsum(size)[:-1]]  # segments: the lags of m[0], its spikes, the lags of m[1], ...
    rho = _mixture_rho(m, np.concatenate(t), start)
    w_all, q_all = np.concatenate(w), np.concatenate(q)
    c = np.zeros((len(m), N_CLASSES, N_CLASSES))
    c[:, 0, 0] = np.add.reduceat(w_all * q_all**2, start)[1::2]
    c[:, 0, RAMP] = c[:, RAMP, 0] = np.add.reduceat(w_all * q_all, start)[1::2]
    for k in range(3):
        c[:, 0, k + 1] = c[:, k + 1, 0] = np.add.reduceat(w_all * q_all * rho[k], start)[1::2]
        c[:, RAMP, k + 1] = c[:, k + 1, RAMP] = np.add.reduceat(w_all * rho[k], start)[0::2]
        for k2 in range(k, 3):
            c[:, k + 1, k2 + 1] = c[:, k2 + 1, k + 1] = np.add.reduceat(w_all * rho[k] * rho[k2], start)[0::2]
    # flicker's terms correlate far beyond 3 m (rho ~ -0.36 / t^2, summing to ~0 over all lags):
    # negligible in the squared sums, not in the ramp's linear one
    terms = n_samples - 2 * m + 1
    last = np.minimum(3 * m, terms - 1)  # the last lag summed above, and its grid step
    lag0 = last + 0.5 * np.where(last <= 3 * _GRID_PER_M, 1.0, 2.0 * last / (6 * _GRID_PER_M))
    tail = (_flicker_tail(m, m, terms, terms, lag0, terms - 0.5, -1.0)
            + _flicker_tail(m, m, terms, terms, lag0, terms - 0.5, 1.0))
    c[:, RAMP, 2] += tail / terms
    c[:, 2, RAMP] = c[:, RAMP, 2]
    return c


_TAIL_POINTS = 400  # geometric grid of ``_flicker_tail``
_TAIL_EXACT = 300.0  # beyond this many factors the flicker correlation is taken as its asymptote


def _flicker_tail(ma: np.ndarray, mb: np.ndarray, n_a: np.ndarray, n_b: np.ndarray, first: np.ndarray,
                  last: np.ndarray | float, sign: float) -> np.ndarray:
    """Sum over lags L = sign u, u from ``first`` to ``last`` (continuous; per pair), of
    N(L) rho(L), rho the flicker cross-correlation of the Allan terms of factors ma at j and
    mb at j + L, N the number of term pairs (``_pair_count``): trapezoid in ln u on
    _TAIL_POINTS points, rho exact (Greenhall's phase autocovariance) up to _TAIL_EXACT x the
    larger factor and its asymptote -2 ma^2 mb^2 / L^2 (over the terms' standard
    deviations) beyond, where the exact form cancels catastrophically. 0 where last <= first."""
    ma, mb = np.asarray(ma, dtype=np.float64), np.asarray(mb, dtype=np.float64)
    first = np.asarray(first, dtype=np.float64)
    last = np.broadcast_to(np.asarray(last, dtype=np.float64), first.shape)
    ok = last > first
    frac = np.linspace(0.0, 1.0, _TAIL_POINTS)
    u = np.where(ok, first, 1.0)[:, None] * (np.where(ok, last / first, 1.0)[:, None] ** frac)
    ma2, mb2 = ma[:, None], mb[:, None]
    p, q = np.divmod(np.arange(9), 3)
    t = sign * u[..., None] + (q * mb2[..., None] - p * ma2[..., None])
    raw = ((_SECOND_DIFF[p] * _SECOND_DIFF[q]) * _phase_acv(t, -1)).sum(-1)
    raw = np.where(u <= _TAIL_EXACT * np.maximum(ma2, mb2), raw, -2.0 * ma2**2 * mb2**2 / u**2)
    sd = _term_sd(ma)[1] * _term_sd(mb)[1]
    f = _pair_count(sign * u, np.asarray(n_a)[:, None], np.asarray(n_b)[:, None]) * raw / sd[:, None] * u
    return np.where(ok, np.trapezoid(f, np.log(u), axis=1), 0.0)


def _mixture_rho(m: np.ndarray, t: np.ndarray, start: np.ndarray) -> np.ndarray:
    """rho_k (rows: MIX_ALPHAS[1:]) at lags ``t`` (units of m) of the Allan terms of factor
    m[i] on the segments start[2 i] .. start[2 i + 2] of t: the exact discrete
    autocorrelations for white and random-walk rate noise up to m = _GRID_PER_M, else
    Greenhall's with F = m (flicker), or F = inf beyond."""
    bounds = np.r_[start[0::2], len(t)]
    owner = np.repeat(np.arange(len(m)), np.diff(bounds))
    fin_m = m <= _GRID_PER_M
    fin = fin_m[owner]
    f = m.astype(np.float64)
    rho = np.empty((3, len(t)))
    for k, alpha in enumerate(MIX_ALPHAS[1:]):
        rho[k, ~fin] = _sz(t[~fin], np.inf, alpha) / _sz(np.zeros(1), np.inf, alpha)
        if alpha in (0, -2):
            for i in np.flatnonzero(fin_m):
                seg = slice(bounds[i], bounds[i + 1])
                rho[k, seg] = _discrete_rho(int(m[i]), alpha, np.round(t[seg] * m[i]))
        elif fin.any():
            rho[k, fin] = _sz(t[fin], f[owner[fin]], alpha) / _sz(np.zeros(len(m)), f, alpha)[owner[fin]]
    return rho


def edf_mixture(fractions: np.ndarray, m, n_samples: int) -> np.ndarray:
    """EDF of overlapping Allan variances over ``n_samples`` gap-free rate samples whose
    noise is a mixture: ``fractions`` (taus x 4, or x 5 with a rate ramp's share last) of
    the Allan variance at each m from white angle, white rate, flicker and random-walk
    rate noise (MIX_ALPHAS) and a deterministic rate ramp (RAMP). Exact for Gaussian
    noise (the Allan terms' autocorrelation is the fraction-weighted sum of the types'):
    exact discrete-time autocorrelations for white angle, white rate and random walk up
    to m = 256, Greenhall's (F = inf) beyond and for flicker. NaN where 2 m > n."""
    m = np.atleast_1d(np.asarray(m, dtype=np.int64))
    return edf_mixture_from(fractions, mixture_matrices(m, n_samples), n_samples - 2 * m + 1)


def with_ramp(fractions: np.ndarray) -> np.ndarray:
    """Mixture fractions over the N_CLASSES classes: a ramp share of 0 added to 4 columns."""
    f = np.asarray(fractions, dtype=np.float64)
    return f if f.shape[-1] == N_CLASSES else np.concatenate([f, np.zeros(f.shape[:-1] + (1,))], axis=-1)


def term_fractions(a, tau) -> np.ndarray:
    """Mixture fractions (taus x N_CLASSES) of the IEEE-952 terms A_n ((deg/h)^2 s^-n, or
    per sample period with ``tau`` in sample periods) at ``tau``: each term's share of the
    model Allan variance sum_n A_n tau^n (Q, N, B, K, R are the classes MIX_ALPHAS, then
    the ramp); white rate noise where the model is empty. (The kernels' own:
    ``scoring.mixture_fractions``.)"""
    parts = np.asarray(tau, dtype=np.float64)[:, None] ** POWERS * np.asarray(a, dtype=np.float64)
    total = parts.sum(1, keepdims=True)
    return np.where(total > 0, parts / np.where(total > 0, total, 1.0), np.eye(N_CLASSES)[1])


def edf_mixture_from(fractions: np.ndarray, matrices: np.ndarray, n_terms_full: np.ndarray) -> np.ndarray:
    """``edf_mixture`` from precomputed ``mixture_matrices`` and gap-free term counts
    n - 2m + 1 (for repeated evaluation inside a fit)."""
    f = with_ramp(fractions)
    with np.errstate(invalid="ignore", divide="ignore"):
        return n_terms_full / np.einsum("ti,tij,tj->t", f, matrices, f)


def mixture_matrices(m, n_samples: int) -> np.ndarray:
    """The (len(m), N_CLASSES, N_CLASSES) matrices of ``edf_mixture`` (NaN where 2 m > n_samples)."""
    return _mixture_matrices(tuple(int(k) for k in np.atleast_1d(m)), int(n_samples))


_MIX_CACHE: dict[tuple[int, int], np.ndarray] = {}  # (m, n) -> its (4, 4) matrix (grids share factors)
_CACHE_MAX = 1 << 14  # entries kept per cache


def _cached_rows(cache: dict, keys: list, compute: Callable[[list], np.ndarray]) -> np.ndarray:
    """The value of each key in ``cache``, the missing ones computed in one call of
    ``compute`` (sorted list of keys -> their values); the cache is emptied when full."""
    todo = sorted({k for k in keys if k not in cache})
    if todo:
        if len(cache) + len(todo) > _CACHE_MAX:
            cache.clear()
        cache.update(zip(todo, compute(todo), strict=True))
    return np.array([cache[k] for k in keys])


@lru_cache(maxsize=256)
def _mixture_matrices(m: tuple, n_samples: int) -> np.ndarray:
    ok = 2 * np.array(m, dtype=np.int64) <= n_samples
    out = np.full((len(m), N_CLASSES, N_CLASSES), np.nan)
    if ok.any():
        keys = [(k, n_samples) for k in np.array(m)[ok].tolist()]
        out[ok] = _cached_rows(_MIX_CACHE, keys, lambda todo: _mixture_rows(
            np.array([k for k, _ in todo], dtype=np.int64), n_samples))
    return out


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


def _term_xcov_raw(lag: np.ndarray, ma: np.ndarray, mb: np.ndarray) -> np.ndarray:
    """Covariance (up to a constant) of the Allan term of factor ``ma`` at j with that of
    ``mb`` at j + lag (arrays of one shape), for each rate noise type MIX_ALPHAS[1:] (first axis)."""
    i, j = np.divmod(np.arange(9), 3)
    t = np.asarray(lag)[..., None] + (j * np.asarray(mb)[..., None] - i * np.asarray(ma)[..., None])
    coef = _SECOND_DIFF[i] * _SECOND_DIFF[j]
    return np.stack([(coef * _phase_acv(t, alpha)).sum(-1) for alpha in MIX_ALPHAS[1:]])


def _pair_count(lag: np.ndarray, ma_terms, mb_terms) -> np.ndarray:
    """Number of term pairs (j, j + lag) with 0 <= j < ma_terms and 0 <= j + lag < mb_terms."""
    return np.maximum(np.minimum(ma_terms, mb_terms - lag) - np.maximum(0, -lag), 0).astype(np.float64)


def _pair_lags(ma: np.ndarray, mb: np.ndarray, n_a: np.ndarray, n_b: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pair index, lag (float) and quadrature weight of the sum over lags of
    ``covariance_matrices`` for each pair of factors (ma[i], mb[i]) with n_a[i], n_b[i]
    terms, pair by pair in increasing lag: the terms' overlap plus 4 max(ma, mb) for
    flicker's tail, every lag on segments up to _EXACT_SEGMENT between the kinks
    p ma - q mb, the kink and 12-point Gauss-Legendre on longer ones."""
    p, q = np.divmod(np.arange(9), 3)
    kinks = p * ma[:, None] - q * mb[:, None]
    reach = 4 * np.maximum(ma, mb)
    lo = np.maximum(kinks.min(1) - reach, -(n_a - 1))
    hi = np.minimum(kinks.max(1) + reach, n_b - 1) + 1
    knots = np.column_stack([kinks, lo, hi, np.zeros_like(lo), n_b - n_a])
    knots = np.sort(np.clip(knots, lo[:, None], hi[:, None]), axis=1)
    distinct = np.ones(knots.shape, dtype=bool)
    distinct[:, 1:] = np.diff(knots, axis=1) > 0
    row, knot = np.nonzero(distinct)[0], knots[distinct]
    seg = row[:-1] == row[1:]  # consecutive distinct knots of one pair bound a segment
    a, b, seg_pair = knot[:-1][seg], knot[1:][seg], row[:-1][seg]
    smooth_seg = b - a > _EXACT_SEGMENT
    count = np.where(smooth_seg, 1 + len(_GAUSS_X), b - a)
    of = np.repeat(np.arange(len(a)), count)
    pos = np.arange(len(of)) - np.repeat(np.cumsum(count) - count, count)
    a, b = a[of], b[of]
    smooth = smooth_seg[of] & (pos > 0)  # on a long segment: the kink lag a itself, then the nodes
    half = 0.5 * (b - a - 1)
    node = np.clip(pos - 1, 0, len(_GAUSS_X) - 1)
    lag = np.where(smooth, half * _GAUSS_X[node] + 0.5 * (a + b), a + pos)
    return seg_pair[of], lag.astype(np.float64), np.where(smooth, half * _GAUSS_W[node], 1.0)


def covariance_matrices(m, n_samples: int) -> np.ndarray:
    """The (len(m), len(m), N_CLASSES, N_CLASSES) matrices C[k, l] = sum over lags of
    N(lag) rho_k(lag) rho_l(lag) of every pair of averaging factors ``m`` (ma, mb) over
    ``n_samples`` gap-free rate samples (all 2 m <= n; cached per grid): for noise types
    MIX_ALPHAS, rho the cross-correlation of the two factors' Allan terms, N the number
    of term pairs at that lag; in the ramp's row C[RAMP, k] = sum over lags of N(lag)
    rho_k(lag) (the covariance of the two means of the terms, which the ramp's constants
    multiply), C[RAMP, RAMP] = 0. The relative covariance of the two Allan variances of a
    mixture is 2 g'Cg / (M_a M_b), g_k = sqrt(f_a,k f_b,k). Lags as ``_pair_lags`` (exact
    for the white and random-walk polynomials); white angle noise correlates terms only
    at the kink lags. All pairs are evaluated in one vectorised pass."""
    return _covariance_matrices(tuple(int(k) for k in np.atleast_1d(m)), int(n_samples))


_PAIR_CACHE: dict[tuple[int, int, int], np.ndarray] = {}
"""(ma, mb, n) -> the pair's (4, 4) matrix (grids whose usable taus differ share their pairs)."""


@lru_cache(maxsize=64)
def _covariance_matrices(m: tuple, n_samples: int) -> np.ndarray:
    ia, ib = np.triu_indices(len(m))
    keys = [(m[a], m[b], n_samples) for a, b in zip(ia, ib, strict=True)]
    c = _cached_rows(_PAIR_CACHE, keys, lambda todo: _cross_matrices(
        np.array([k[0] for k in todo], dtype=np.int64), np.array([k[1] for k in todo], dtype=np.int64), n_samples))
    out = np.empty((len(m), len(m), N_CLASSES, N_CLASSES))
    out[ia, ib] = c
    out[ib, ia] = c
    return out


def _cross_matrices(ma: np.ndarray, mb: np.ndarray, n_samples: int) -> np.ndarray:
    """``covariance_matrices``' matrix of each pair of factors (ma[i], mb[i])."""
    n_a, n_b = n_samples - 2 * ma + 1, n_samples - 2 * mb + 1
    pair, lag, w = _pair_lags(ma, mb, n_a, n_b)
    w = w * _pair_count(lag, n_a[pair], n_b[pair])
    # white angle noise: X is white, so terms correlate only at the kink lags p ma - q mb
    # (each distinct kink once, its weights summed)
    p, q = np.divmod(np.arange(9), 3)
    kinks = p * ma[:, None] - q * mb[:, None]
    k_pair, k_lag, inv = _distinct_rows(np.repeat(np.arange(len(ma)), 9), kinks.ravel())
    rho_q = np.bincount(inv, weights=np.tile(_SECOND_DIFF[p] * _SECOND_DIFF[q], len(ma)),
                        minlength=len(k_lag)) / 6.0
    w_q = _pair_count(k_lag, n_a[k_pair], n_b[k_pair])
    c = np.zeros((len(ma), N_CLASSES, N_CLASSES))
    c[:, 0, 0] = np.bincount(k_pair, weights=w_q * rho_q**2, minlength=len(ma))
    c[:, 0, RAMP] = c[:, RAMP, 0] = np.bincount(k_pair, weights=w_q * rho_q, minlength=len(ma))
    scale = _term_sd(ma) * _term_sd(mb)
    rho = _term_xcov_raw(lag, ma[pair], mb[pair]) / scale[:, pair]
    rho_at_kinks = _term_xcov_raw(k_lag, ma[k_pair], mb[k_pair]) / scale[:, k_pair]
    for k in range(3):
        c[:, 0, k + 1] = c[:, k + 1, 0] = np.bincount(k_pair, weights=w_q * rho_q * rho_at_kinks[k],
                                                      minlength=len(ma))
        c[:, RAMP, k + 1] = c[:, k + 1, RAMP] = np.bincount(pair, weights=w * rho[k], minlength=len(ma))
    for k in range(3):
        for k2 in range(k, 3):
            c[:, k + 1, k2 + 1] = c[:, k2 + 1, k + 1] = np.bincount(pair, weights=w * rho[k] * rho[k2],
                                                                    minlength=len(ma))
    # flicker's long tail beyond the lags summed (see _mixture_rows)
    lo = np.full(len(ma), np.inf)
    hi = np.full(len(ma), -np.inf)
    np.minimum.at(lo, pair, lag)
    np.maximum.at(hi, pair, lag)
    tail = (_flicker_tail(ma, mb, n_a, n_b, hi + 0.5, n_b - 0.5, 1.0)
            + _flicker_tail(ma, mb, n_a, n_b, -lo + 0.5, n_a - 0.5, -1.0))
    c[:, RAMP, 2] += tail
    c[:, 2, RAMP] = c[:, RAMP, 2]
    return c


def _term_sd(m: np.ndarray) -> np.ndarray:
    """Standard deviation (the constant of ``_term_xcov_raw``) of an Allan term of each
    factor m (columns) for each noise type MIX_ALPHAS[1:] (rows)."""
    return np.sqrt(_term_xcov_raw(np.zeros(len(m)), m, m))


def _distinct_rows(group: np.ndarray, value: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct (group, value) pairs (group, value, each input's index among them)."""
    key, inv = np.unique(np.stack([group, value], axis=1), axis=0, return_inverse=True)
    return key[:, 0], key[:, 1].astype(np.float64), inv.ravel()


def avar_relative_covariance(fractions: np.ndarray, matrices: np.ndarray, n_terms_full: np.ndarray) -> np.ndarray:
    """Covariance of overlapping Allan variance estimates across taus, relative to the
    product of their expectations (T x T; diagonal 2 / EDF), for Gaussian noise whose
    Allan variance at each tau is split by ``fractions`` (T x 4, MIX_ALPHAS, or x 5 with a
    deterministic rate ramp's share last) over white angle, white rate, flicker and
    random-walk rate noise: exact (it is a quadratic form in the data plus the ramp's
    linear one: cov = 2 tr(A S B S) + c_a c_b cov(mean e_a, mean e_b)), from
    ``covariance_matrices`` and the gap-free term counts n - 2 m + 1."""
    f = with_ramp(fractions)
    g = np.sqrt(f[:, None, :] * f[None, :, :])
    return 2.0 * np.einsum("abk,abkl,abl->ab", g, matrices, g) / np.outer(n_terms_full, n_terms_full)


@lru_cache(maxsize=64)
def _quantiles(confidence: float) -> tuple[float, float]:
    lo = min(abs(confidence), abs(1.0 - confidence)) / 2.0
    return lo, 1.0 - lo


MIN_EDF = 1.0
"""Below this EDF a deviation gets no interval (``chi2_factors``: NaN bounds, printed as
"-"): with EDF << 1 nearly all of chi-square's mass lies near 0, so both quantiles can
fall below the EDF and the interval excludes its own estimate (an EDF of 0.07 gave
21.341 [61.635, 1.3915e+12]); such a tau holds less than one independent Allan term."""


def chi2_factors(edf: np.ndarray, confidence: float = CONFIDENCE) -> tuple[np.ndarray, np.ndarray]:
    """Interval factors (lo / sigma_hat, hi / sigma_hat) of a deviation with ``edf``
    degrees of freedom at two-sided ``confidence`` (NIST SP1065 eq. 45); NaN (no
    interval) where the EDF is below MIN_EDF or the interval would not hold the estimate
    (factors not around 1). An EDF row broadcast over windows (the gap-free case) gives one
    row of factors, cached: streaming asks for the same row block after block."""
    edf = np.asarray(edf, dtype=np.float64)
    while edf.ndim > 1 and edf.strides[0] == 0 and edf.shape[0] > 1:
        edf = edf[:1]  # the same row for every window
    if edf.ndim and edf.size == edf.shape[-1]:  # one row
        f_lo, f_hi = _row_factors(np.ascontiguousarray(edf).tobytes(), float(confidence))
        return f_lo.reshape(edf.shape), f_hi.reshape(edf.shape)
    return _factors(edf, float(confidence))


@lru_cache(maxsize=256)
def _row_factors(edf: bytes, confidence: float) -> tuple[np.ndarray, np.ndarray]:
    """``_factors`` of one EDF row given as float64 bytes (read-only results)."""
    f_lo, f_hi = _factors(np.frombuffer(edf, np.float64), confidence)
    f_lo.flags.writeable = f_hi.flags.writeable = False
    return f_lo, f_hi


def _factors(edf: np.ndarray, confidence: float) -> tuple[np.ndarray, np.ndarray]:
    """``chi2_factors`` entry by entry: chi2 quantiles once per distinct EDF value."""
    from scipy.special import gammaincinv  # imported here: scipy costs start-up time

    q_lo, q_hi = _quantiles(confidence)
    ok = np.isfinite(edf) & (edf >= MIN_EDF)
    f_lo = np.full(edf.shape, np.nan)
    f_hi = np.full(edf.shape, np.nan)
    if ok.any():
        u, inv = np.unique(edf[ok], return_inverse=True)
        with np.errstate(divide="ignore", over="ignore"):
            # the chi2 quantile with u degrees of freedom at q is 2 gammaincinv(u / 2, q)
            f_lo[ok] = np.sqrt(u / (2.0 * gammaincinv(u / 2.0, q_hi)))[inv]
            f_hi[ok] = np.sqrt(u / (2.0 * gammaincinv(u / 2.0, q_lo)))[inv]
    excludes = ~((f_lo <= 1.0) & (f_hi >= 1.0))  # NaN too; a safeguard: at EDF >= 1 the quantiles straddle it
    f_lo[excludes] = np.nan
    f_hi[excludes] = np.nan
    return f_lo, f_hi


def chi2_bounds(adev: np.ndarray, edf: np.ndarray, confidence: float = CONFIDENCE) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided ``confidence`` interval (lo, hi) of a deviation ``adev`` (any unit) with
    ``edf`` degrees of freedom: adev times ``chi2_factors``."""
    adev = np.asarray(adev, dtype=np.float64)
    f_lo, f_hi = chi2_factors(np.broadcast_to(np.asarray(edf, dtype=np.float64), adev.shape), confidence)
    return adev * f_lo, adev * f_hi
