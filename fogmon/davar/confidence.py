"""Chi-square confidence intervals of the overlapping Allan deviation.

sigma_hat^2 ~ sigma^2 chi2_nu / nu with nu from Greenhall & Riley's EDF algorithm
(``allantools.ci.edf_greenhall``, overlapping ADEV, d = 2). The noise type alpha
(S_y ~ f^alpha) per tau comes from the dominant IEEE-952 term (``ALPHA_OF_TERM``) or from
the caller. When gaps remove terms, nu is scaled by the fraction of terms still valid.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from allantools.ci import edf_greenhall
from scipy.stats import chi2

ALPHA_OF_TERM = np.array([2, 0, -1, -2, -2])
"""Power-law exponent alpha of each IEEE-952 term Q, N, B, K, R (R treated as random walk)."""


@lru_cache(maxsize=1 << 16)
def _edf_greenhall(alpha: int, m: int, n_samples: int) -> float:
    # Greenhall counts phase points: n rate samples are n + 1 phase points.
    return float(edf_greenhall(alpha, 2, m, n_samples + 1, overlapping=True, modified=False))


def edf_full(alpha, m, n_samples: int) -> np.ndarray:
    """Greenhall EDF of an overlapping ADEV with averaging factors ``m`` over
    ``n_samples`` gap-free rate samples for noise type(s) ``alpha`` (scalar or per m).
    NaN where 2 m > n_samples. Cached per (alpha, m, n_samples)."""
    m = np.atleast_1d(np.asarray(m, dtype=np.int64))
    alpha = np.broadcast_to(np.asarray(alpha, dtype=np.int64), m.shape)
    return np.array([_edf_greenhall(int(a), int(k), int(n_samples)) if 2 * k <= n_samples else np.nan
                     for a, k in zip(alpha, m)])


def edf_effective(edf_gapless: np.ndarray, m: np.ndarray, n_samples: int, n_terms: np.ndarray) -> np.ndarray:
    """Scale gap-free EDF (over m, last axis) by the fraction of overlapping terms that
    are valid, ``n_terms / (n_samples - 2 m + 1)``; NaN where no term is valid."""
    n_terms = np.asarray(n_terms)
    full = np.maximum(n_samples - 2 * np.asarray(m) + 1, 1)
    with np.errstate(invalid="ignore"):
        return np.where(n_terms > 0, edf_gapless * (n_terms / full), np.nan)


@lru_cache(maxsize=64)
def _quantiles(confidence: float) -> tuple[float, float]:
    lo = min(abs(confidence), abs(1.0 - confidence)) / 2.0
    return lo, 1.0 - lo


def chi2_bounds(adev: np.ndarray, edf: np.ndarray, confidence: float = 0.683) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided ``confidence`` interval (lo, hi) of a deviation ``adev`` (any unit) with
    ``edf`` degrees of freedom (NIST SP1065 eq. 45). chi2 quantiles are evaluated once
    per distinct EDF value."""
    adev = np.asarray(adev, dtype=np.float64)
    edf = np.broadcast_to(np.asarray(edf, dtype=np.float64), adev.shape)
    q_lo, q_hi = _quantiles(float(confidence))
    ok = np.isfinite(edf) & (edf > 0)
    f_lo = np.full(adev.shape, np.nan)
    f_hi = np.full(adev.shape, np.nan)
    if ok.any():
        u, inv = np.unique(edf[ok], return_inverse=True)
        with np.errstate(divide="ignore", over="ignore"):  # tiny EDF: hi is +inf
            f_lo[ok] = np.sqrt(u / chi2.ppf(q_hi, u))[inv]
            f_hi[ok] = np.sqrt(u / chi2.ppf(q_lo, u))[inv]
    return adev * f_lo, adev * f_hi
