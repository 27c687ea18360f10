"""The noise mixture behind a whole record's per-tau ADEV intervals (``batch.oadev``).

The EDF (and the exact shape) of each tau's interval is that of the noise mixture the
quick IEEE-952 fit (``fit.quick_avar_terms``) predicts. At the longest taus the interval
hangs on two shares the record pins down poorly (docs/davar.md, "Confidence intervals"
and "Calibration"):

- A rate ramp R is deterministic: its share of the Allan variance has no sampling
  variance, so reading it as a ramp narrows the interval several-fold. A chance-high
  Allan variance at the last taus, fitted as a ramp, made the interval narrowest where
  the estimate was too high (such records' 95 % intervals at the last tau covered
  0-30 %). So the share counts as deterministic only where the record's fit rejects
  R = 0 at DETERMINISTIC_Z (every other term refitted, K among them: "more than the
  other terms explain without a ramp") and identifies no random walk K beside it,
  else as random-walk rate noise, which has about the same Allan variance slope. A random
  walk the record shows draws trends of its own, which the ramp term absorbs.
- Beside a deterministic ramp, K is the share the EDF is most sensitive to: even a few %
  of random walk lowers it several-fold (the ramp's constant multiplies the Allan terms'
  mean, whose variance a random walk makes large), and the quick fit trades K against R.
  K is then the quick fit's estimate on the record with its least-squares line removed (a
  deterministic ramp has no Allan variance there, a real random walk keeps most of its
  own), whether or not that record identifies K. Its nonnegative estimate is above zero
  in about a quarter of records without any K, which widens their longest taus'
  intervals (they over-cover); counting it only where identified (2026-11-30) made the
  intervals of records with a real K near its limit beside a strong ramp under-cover
  (K 1, R 3 over 3.6 h at 10 Hz: 87.0-88.7 % at 95 % at the three longest taus, 300
  records; K 1.5, R 4 over 4.5 h at 1 Hz: 89.3-91.3 %), records the calibration's own models
  did not contain. An interval that errs should err wide.

Measured on validation/calibration.py's records (1000 per model, seed 3, a one-off script
reading each record's saved sums): R read as deterministic in 59 records of all five
terms over 22 min (R 5 deg/h^2 near its limit, K 3) at the identification's z 1.96,
7 at 3.09; the 95 % intervals of all its records at 163.8 / 327.7 s covered 89.9 / 88.1 %, now 91.9 /
91.2 % (seed 1: 92.1 / 91.2 -> 93.8 / 93.5 %). N 0.05, B 0.2, R 1 over 9 h (no K): K
from the detrended record was above zero in 249 of 984 records, whose 68.3 % intervals
at 1024-8192 s covered 76-88 % (the others 69-71 %). The coverage with these rules is
in docs/davar.md, "Calibration".
Assumptions: Gaussian noise of the five terms, a ramp linear over the record.
"""
from __future__ import annotations

from statistics import NormalDist

import numpy as np

from fogmon.davar.confidence import MIX_ALPHAS, RAMP, edf_mixture_from, mixture_matrices, term_fractions
from fogmon.davar.fit import CurveFit, anchored_edf, fit_curve, quick_avar_terms
from fogmon.davar.theory import NAMES

K, R = NAMES.index("K_dphsh"), NAMES.index("R_dphh")  # the random walk's and the ramp's columns
#: the random-walk rate noise class among the mixture's
RANDOM_WALK = MIX_ALPHAS.index(-2)
DETERMINISTIC_Z = NormalDist().inv_cdf(0.999)
"""The ramp's share counts as deterministic only where the test of R = 0 rejects at this
signed root (one-sided 0.1 %, z 3.09), not at identification's 1.96: a ramp read as
deterministic by chance leaves its record's longest-tau intervals covering 0-30 %, so
where there is no ramp the reading should come about once in a thousand records (N, B,
K over 1.8 h, no R: 4 of 1000 at seeds 1 and 3)."""


def record_fit(tau_s, avar, m, n_terms, n_samples: int) -> CurveFit:
    """The record's fit (``fit.fit_curve``; its identification test, the one ``fit_noise``
    and ``fogmon replay`` report, and the test's ``score_z``) of the Allan variance
    ``avar`` (deg/h)^2 at ``tau_s`` (s)."""
    return fit_curve(tau_s, avar, m, n_terms, n_samples, limits="unidentified")


def deterministic_ramp(fit: CurveFit) -> bool:
    """Whether the ramp's share counts as deterministic, and K then comes from the
    detrended record (``detrended_k``): R = 0 rejected at DETERMINISTIC_Z, K not identified."""
    z = np.asarray(fit.score_z, dtype=np.float64)
    return bool(np.isfinite(z[R]) and z[R] >= DETERMINISTIC_Z and not fit.identifiable[K])


def detrended_k(avar, m, n_terms, n_samples: int) -> float:
    """A_K (tau in sample periods, as the quick fit's terms) beside a deterministic ramp:
    the quick fit's estimate on the Allan variance ``avar`` (deg/h)^2 at factors ``m`` of
    the record with its least-squares line removed."""
    return float(quick_avar_terms(np.asarray(m, dtype=np.float64), avar, m, n_terms, n_samples)[K])


def fractions(terms, deterministic: bool, m, k_detrended: float | None = None) -> np.ndarray:
    """Mixture fractions (taus x N_CLASSES) at factors ``m`` of the quick-fit ``terms``
    (tau in sample periods) under the module's rules: the ramp's share ``deterministic``
    (``deterministic_ramp``), with K at ``k_detrended`` when given; else random-walk rate
    noise."""
    a = np.array(terms, dtype=np.float64)
    if deterministic and k_detrended is not None:
        a[K] = k_detrended
    f = term_fractions(a, np.asarray(m, dtype=np.float64))
    if not deterministic:
        f = f.copy()
        f[:, RANDOM_WALK] += f[:, RAMP]
        f[:, RAMP] = 0.0
    return f


def edf_row(fractions_m: np.ndarray, m, n_samples: int) -> np.ndarray:
    """Gap-free EDF per tau of the mixture ``fractions_m`` (taus x N_CLASSES) at factors
    ``m`` over ``n_samples`` samples (``confidence.edf_mixture_from``), exact at the
    anchors of ``fit.anchored_edf`` and interpolated between them as ``fit.dense_grid_edf``;
    NaN where 2 m > n_samples."""
    m = np.asarray(m, dtype=np.int64)
    out = np.full(len(m), np.nan)
    ok = np.flatnonzero(2 * m <= n_samples)
    if not len(ok):
        return out
    mo, fo = m[ok], fractions_m[ok]
    out[ok] = anchored_edf(mo, lambda i: edf_mixture_from(fo[i], mixture_matrices(mo[i], n_samples),
                                                          n_samples - 2 * mo[i] + 1))
    return out
