"""The exact shape of the Allan variance's sampling distribution at the longest taus.

The overlapping Allan variance of Gaussian noise is a quadratic form of its terms e_j:
sigma_hat^2 / sigma^2 = X = sum_k lambda_k (z_k + beta_k)^2, z_k independent standard
normals, lambda_k the eigenvalues of the terms' covariance / (M sigma^2), beta_k from a
deterministic rate ramp (which adds the same constant to every term). Its variance is
2 / EDF (confidence.edf_mixture); chi2_EDF / EDF has that variance but not the shape:
where the record holds few independent terms (M / m small) a few lambda_k carry X, and at
m = n / 4 (M / m = 2) the chi-square interval of white rate noise covers 73.1 % at
68.3 % and 97.0 % at 95 %; a three-cumulant (Pearson III) shape 68.8 % and 92.3 %
(the exact term covariance of 256 samples: its eigenvalues and 4e5 draws each).

Here, where M / m <= SHAPE_RATIO: the terms' correlation operator on a grid of
_PER_M points per m (midpoint weights: the Allan terms' autocorrelations are smooth in
lag / m, and M / m <= SHAPE_RATIO keeps the grid at most SHAPE_RATIO x _PER_M points),
its eigenvalues for the mixture's noise types (white rate, flicker, random walk; white
angle noise, whose terms decorrelate within m samples, and the ramp enter as the
constant and the non-central means they give), the quantiles of X by the Lugannani-Rice
saddlepoint approximation (Kuonen 1999), and the spread of X about 1 rescaled to the
exact variance 2 / EDF (the grid's own variance is 0-10 % above it: white rate noise at
m = n / 4 +9 %, flicker and random walk +0.1-1.2 %).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from fogmon.davar.confidence import _GRID_PER_M, _sz
from fogmon.davar.taus import anchors

SHAPE_RATIO = 16.0
"""Taus with M / m above this (M = n - 2 m + 1 terms) keep the chi-square shape: there
its coverage is within 1 % of nominal (white rate noise at M / m = 14: 69.1 % at
68.3 %, 95.5 % at 95 %) and the EDF at least ~15 for every noise type."""
_PER_M = 4  # grid points per m
_MAX_POINTS = 48  # and at most this many (at M / m = 16: 3 per m)
_SMOOTH = (1, 2, 3)  # mixture classes on the grid: white rate, flicker, random walk (confidence.MIX_ALPHAS)
_ALPHAS = (0, -1, -2)
_RAMP = 4
_BISECT = 52


@lru_cache(maxsize=512)
def _grid_rho(m: int, n_samples: int) -> np.ndarray:
    """The correlation (normalised at lag 0) of the Allan terms of factor m of each noise
    type _ALPHAS (rows) at the lags k h, k = 0 .. L - 1, of a grid of L points with step h
    = M / L samples over the M = n - 2 m + 1 terms: L = _PER_M per m, at most _MAX_POINTS
    and at most M (then the terms themselves)."""
    terms = n_samples - 2 * m + 1
    size = min(terms, max(1, int(round(terms * _PER_M / m))), _MAX_POINTS)
    t = np.arange(size) * (terms / size) / m
    f = float(m) if m <= _GRID_PER_M else np.inf
    return np.array([_sz(t, f, a) / _sz(np.zeros(1), f, a) for a in _ALPHAS])


def _mixture_eigen(fractions: np.ndarray, m: int, n_samples: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(lambda_k, omega_k = lambda_k beta_k^2, constant) of X for one tau's mixture
    ``fractions`` (5 classes, summing to 1): X = const + (1 / L) sum_i (e_i + c)^2 over the
    grid's L terms e_i (covariance: the fraction-weighted correlations), c^2 the ramp's share."""
    from scipy.linalg import eigh, toeplitz

    rho = _grid_rho(m, n_samples)
    size = rho.shape[1]
    col = np.asarray(fractions)[list(_SMOOTH)] @ rho
    mu, v = eigh(toeplitz(col), driver="evd", check_finite=False)  # evd: 0.3 ms at 48 points
    lam = np.maximum(mu, 0.0) / size
    proj = (v.sum(axis=0) ** 2) / size  # (v_k' 1)^2 / L: the share of the mean along v_k
    return lam, float(fractions[_RAMP]) * proj, float(fractions[0])


def _cgf(t: np.ndarray, lam: np.ndarray, omega: np.ndarray, const: float):
    """K(t), K'(t), K''(t) of X at each t (rows), eigenvalues on the last axis."""
    d = 1.0 - 2.0 * t[:, None] * lam
    k0 = (-0.5 * np.log(d) + omega * t[:, None] / d).sum(1) + const * t
    k1 = (lam / d + omega / d**2).sum(1) + const
    k2 = (2.0 * lam**2 / d**2 + 4.0 * lam * omega / d**3).sum(1)
    return k0, k1, k2


def _cdf_at(t: np.ndarray, lam: np.ndarray, omega: np.ndarray, const: float) -> tuple[np.ndarray, np.ndarray]:
    """(x, P(X <= x)) at the saddlepoints ``t``: x = K'(t), Lugannani-Rice."""
    from scipy.special import ndtr

    k0, x, k2 = _cgf(t, lam, omega, const)
    w = np.sign(t) * np.sqrt(np.maximum(2.0 * (t * x - k0), 0.0))
    u = t * np.sqrt(k2)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = ndtr(w) + np.exp(-0.5 * w**2) / np.sqrt(2.0 * np.pi) * (1.0 / w - 1.0 / u)
    return x, np.where(np.abs(w) > 1e-6, np.clip(p, 0.0, 1.0), 0.5)


def quantiles(lam: np.ndarray, omega: np.ndarray, const: float, q: np.ndarray) -> np.ndarray:
    """Quantiles of X = const + sum_k lambda_k (z_k + beta_k)^2 (omega_k = lambda_k
    beta_k^2) at probabilities ``q``: bisection of the saddlepoint t in
    (-inf, 1 / (2 max lambda)) for P(X <= K'(t)) = q (monotone in t)."""
    q = np.asarray(q, dtype=np.float64)
    top = 1.0 / (2.0 * max(float(lam.max()), 1e-300))
    # t = top (1 - e^v): v from -40 (next to the pole) to +25 (far below the mean)
    lo = np.full(q.shape, -40.0)
    hi = np.full(q.shape, 25.0)
    for _ in range(_BISECT):
        mid = 0.5 * (lo + hi)
        _, p = _cdf_at(top * (1.0 - np.exp(mid)), lam, omega, const)
        above = p > q  # t too large: move towards larger v (smaller t)
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    return _cdf_at(top * (1.0 - np.exp(0.5 * (lo + hi))), lam, omega, const)[0]


def shape_applies(m, n_samples: int) -> np.ndarray:
    """The taus (factors ``m`` of ``n_samples`` gap-free samples) whose interval takes the
    exact shape: 1 <= M / m <= SHAPE_RATIO (below, at m = n / 2, a single term: chi-square
    with one degree of freedom is exact for noise, where the saddlepoint is 1 % off)."""
    m = np.asarray(m, dtype=np.float64)
    ratio = (n_samples - 2 * m + 1) / m
    return (ratio >= 1.0) & (ratio <= SHAPE_RATIO)


def shape_factors(fractions: np.ndarray, m, n_samples: int, edf: np.ndarray, confidence: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Interval factors (lo / sigma_hat, hi / sigma_hat) of a deviation at two-sided
    ``confidence`` per tau from the exact shape of X for the mixture ``fractions`` (taus
    x 5: confidence.MIX_ALPHAS then the ramp) at the taus where ``shape_applies``, its
    variance 2 / ``edf``; NaN elsewhere (and where the lower quantile is not above 0).
    The shape (the quantiles in standard deviations) is exact at the factors
    ``taus.anchors`` picks and interpolated in log m between them: 4 ms per tau exactly,
    so an "all" grid of 2^15 samples took 26 s for its 6372 shaped taus; interpolated,
    0.3 s and its factors within 0.3 % of the exact ones (tests/davar/test_shape.py),
    below the grid's own step in L (module docstring)."""
    m = np.asarray(m, dtype=np.int64)
    edf = np.asarray(edf, dtype=np.float64)
    tail = min(confidence, 1.0 - confidence) / 2.0
    q = np.array([tail, 1.0 - tail])
    f_lo = np.full(len(m), np.nan)
    f_hi = np.full(len(m), np.nan)
    idx = np.flatnonzero(shape_applies(m, n_samples) & np.isfinite(edf) & (edf > 0))
    if not len(idx):
        return f_lo, f_hi
    # the standardized quantiles (X - 1) / sd(X), exact at the anchors, interpolated in log m between
    at = idx[anchors(m[idx])]
    g = np.full((len(at), 2), np.nan)
    for k, i in enumerate(at):
        lam, omega, const = _mixture_eigen(np.asarray(fractions[i], dtype=np.float64), int(m[i]), n_samples)
        var = float((2.0 * lam**2 + 4.0 * lam * omega).sum())
        if var > 0:
            g[k] = (quantiles(lam, omega, const, q) - 1.0) / np.sqrt(var)
    good = np.isfinite(g[:, 0])
    if not good.any():
        return f_lo, f_hi
    lg = np.log2(m[idx])
    lg_at = np.log2(m[at[good]])
    x_lo = 1.0 + np.sqrt(2.0 / edf[idx]) * np.interp(lg, lg_at, g[good, 0])
    x_hi = 1.0 + np.sqrt(2.0 / edf[idx]) * np.interp(lg, lg_at, g[good, 1])
    ok = x_lo > 0
    f_lo[idx[ok]], f_hi[idx[ok]] = 1.0 / np.sqrt(x_hi[ok]), 1.0 / np.sqrt(x_lo[ok])
    f_lo[at[~good]] = f_hi[at[~good]] = np.nan  # an anchor without a shape keeps chi-square's
    return f_lo, f_hi
