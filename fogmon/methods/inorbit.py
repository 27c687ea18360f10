"""In-orbit evaluation (docs/methods.md): a low-frequency periodic term (the orbit) and
glitches spoil the Allan variance of on-orbit gyro telemetry. First differencing
removes slow terms, the Pauta (3-sigma) criterion removes glitches, and the angle
random walk follows from the spread of the cleaned differences; bias instability is the
standard deviation of per-orbit means; a Daubechies-4 wavelet decomposition shows in
which frequency band the energy sits."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pywt
from scipy.optimize import brentq
from scipy.stats import norm

from fogmon.errors import FogmonError

#: Orbit period of the in-orbit paper's spacecraft, s.
ORBIT_PERIOD_S = 5580.0
#: The iterated k-sigma Pauta criterion keeps a nonzero share of Gaussian data only for
#: k > sqrt(3) (the truncated-normal std factor tends to a / sqrt(3) as a -> 0).
PAUTA_K_MIN = math.sqrt(3.0)
#: Fewest samples ``arw_from_differences`` reads a white-rate level from.
ARW_MIN_SAMPLES = 100


def _truncated_std_factor(a: float) -> float:
    """std of a unit normal truncated to |x| <= a."""
    return math.sqrt(1.0 - 2.0 * a * norm.pdf(a) / (2.0 * norm.cdf(a) - 1.0))


def pauta_mask(x, k: float = 3.0, max_iter: int = 50) -> np.ndarray:
    """Pauta criterion: repeatedly reject samples farther than k standard deviations
    from the mean of the samples kept so far. Returns the mask of kept samples."""
    x = np.asarray(x, float)
    keep = np.isfinite(x)
    for _ in range(max_iter):
        mu, sd = x[keep].mean(), x[keep].std()
        new = keep & (np.abs(x - mu) <= k * sd)
        if new.sum() == keep.sum():
            break
        keep = new
    return keep


def pauta_consistency(k: float = 3.0) -> float:
    """Factor by which the iterated k-sigma Pauta criterion shrinks the std of Gaussian
    data: the fixed point a = k f(a) with f the truncated-normal std factor."""
    if not PAUTA_K_MIN < k < math.inf:
        raise FogmonError(f"Pauta k must be finite and > sqrt(3) = {PAUTA_K_MIN:.4g}, got {k}")
    a = brentq(lambda a: a - k * _truncated_std_factor(a), 1e-3, k)
    return _truncated_std_factor(a)


@dataclass(frozen=True)
class DifferenceArw:
    """Angle random walk from cleaned first differences: ``N_dpsh`` (deg/sqrt(h)), the
    per-sample white-rate std ``sigma_dph`` (deg/h) and the ``outliers`` rejected."""

    N_dpsh: float
    sigma_dph: float
    outliers: int


def arw_from_differences(rate_dph, sample_rate_hz: float, k: float = 3.0) -> DifferenceArw:
    """First-difference the rate (removing slow terms such as the orbital one), reject
    glitches with the Pauta criterion, and read the white-rate level: var(diff) = 2
    sigma^2 for white rate noise, corrected for the Pauta truncation; N = sigma /
    (60 sqrt(fs)). Valid when white rate noise dominates at tau0 (Q negligible)."""
    y = np.asarray(rate_dph, float)
    if len(y) < ARW_MIN_SAMPLES:
        raise FogmonError(f"{len(y)} samples are too few for the angle random walk from first differences "
                          f"(need >= {ARW_MIN_SAMPLES})")
    d = np.diff(y)
    keep = pauta_mask(d, k)
    sigma = d[keep].std(ddof=1) / pauta_consistency(k) / math.sqrt(2.0)
    return DifferenceArw(sigma / (60.0 * math.sqrt(sample_rate_hz)), float(sigma), int((~keep).sum()))


def cycle_bias_instability(t_s, rate_dph, period_s: float = ORBIT_PERIOD_S) -> tuple[float, int]:
    """Bias instability as the in-orbit paper defines it: the standard deviation (deg/h)
    of the rate averaged over each complete cycle of ``period_s``; and the number of
    complete cycles used (at least 2 needed)."""
    t = np.asarray(t_s, float)
    y = np.asarray(rate_dph, float)
    k = np.floor((t - t[0]) / period_s).astype(np.int64)
    ncyc = int((t[-1] - t[0]) // period_s)
    if ncyc < 2:
        raise FogmonError(f"the record holds {ncyc} complete {period_s:g} s cycles (`period_s`); need >= 2")
    sel = k < ncyc
    means = np.bincount(k[sel], weights=y[sel]) / np.bincount(k[sel])
    return float(means.std(ddof=1)), ncyc


def wavelet_energy(rate_dph, sample_rate_hz: float, wavelet: str = "db4", level: int | None = None):
    """Energy of each Daubechies-4 (default) wavelet level of the mean-removed rate: list
    of (band_lo_hz, band_hi_hz, energy_fraction) from the finest detail band to the
    approximation. The periodized transform is orthogonal, so the fractions are a true
    partition of the signal energy."""
    y = np.asarray(rate_dph, float) - np.mean(rate_dph)
    w = pywt.Wavelet(wavelet)
    lmax = pywt.dwt_max_level(len(y), w.dec_len)
    level = lmax if level is None else min(level, lmax)
    coeffs = pywt.wavedec(y, w, level=level, mode="periodization")  # orthogonal: energies add up
    e = np.array([float(np.sum(c ** 2)) for c in coeffs])
    e /= e.sum()
    out = []
    for j in range(1, level + 1):  # detail level j covers fs/2^(j+1) .. fs/2^j
        out.append((sample_rate_hz / 2 ** (j + 1), sample_rate_hz / 2 ** j, float(e[level - j + 1])))
    out.append((0.0, sample_rate_hz / 2 ** (level + 1), float(e[0])))
    return out
