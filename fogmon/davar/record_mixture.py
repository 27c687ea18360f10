"""The noise mixture behind a whole record's per-tau ADEV intervals (``batch.oadev``).

The EDF (and the exact shape) of each tau's interval is that of the noise mixture the
quick IEEE-952 fit (``fit.quick_avar_terms``) predicts. At the longest taus the interval
hangs on two shares the record pins down poorly (docs/davar.md, "Calibration"):

- A rate ramp R is deterministic: its share of the Allan variance has no sampling
  variance. A chance-high Allan variance at the last taus, fitted as a ramp where there
  is none, made the interval narrowest where the estimate was too high. So the ramp's
  share counts as deterministic only when the record's fit identifies R (``identified``:
  the test ``fit_noise`` reports) and no random walk K beside it, else as random-walk
  rate noise, which has about the same Allan variance slope. A random walk the record
  shows draws trends of its own, which the ramp term absorbs: the fit cannot say which
  part of the ramp's share is deterministic (all five terms over 2.9 h, below: of 400
  records, the 15 whose 95 % interval missed at the last tau had, in the median, a ramp
  1.6x the true one and an Allan variance 2.2x the truth there).
- Beside an identified ramp, a random walk K that the record does not identify is a
  share the fit trades against R, and even a few % of random walk lowers the EDF there
  several-fold (the ramp's constant multiplies the Allan terms' mean, whose variance a
  random walk makes large). Its estimate is then taken from the record with its
  least-squares line removed (``batch.record_statistics``): a deterministic ramp has no Allan
  variance there, so K no longer trades against R, while a real random walk keeps most
  of its own.

Measured on validation/calibration.py's records (seed 1): N 0.05, B 0.2, R 1 over 9 h
(no K; 200 records): K was fitted > 0 beside a ramp in 43 % of the records (EDF 20-40
where the true one is 220-300, the 68.3 % interval covering 81-83 %), 20 % after the
detrended rule (69-72.5 %). All five terms over 2.9 h, K 0.3, R 0.6 (1000 records, both
identified in 37 %): the 95 % intervals at 1311 and 2621 s covered 90.0 and 89.6 % with
the ramp deterministic beside an identified K, 93.7 and 93.8 % without (the 68.3 %
ones 65.8 and 69.9 -> 69.4 and 74.1 %: conservative there, where a real ramp is counted
as random). Assumptions: Gaussian noise of the five terms, a ramp linear over the record.
"""
from __future__ import annotations

import numpy as np

from fogmon.davar.confidence import MIX_ALPHAS, RAMP, edf_mixture_from, mixture_matrices, term_fractions
from fogmon.davar.fit import anchored_edf, fit_curve

K, R = 3, 4  # indices of K and R among the five IEEE-952 terms (Q, N, B, K, R)
#: the random-walk rate noise class among the mixture's
RANDOM_WALK = MIX_ALPHAS.index(-2)


def identified(tau_s, avar, m, n_terms, n_samples: int) -> np.ndarray:
    """Mask over the five IEEE-952 terms that the record's fit identifies (``fit.fit_curve``'s
    test, the one ``fit_noise`` and ``fogmon replay`` report) for the Allan variance
    ``avar`` (deg/h)^2 at ``tau_s`` (s)."""
    return np.asarray(fit_curve(tau_s, avar, m, n_terms, n_samples, limits="unidentified").identifiable, dtype=bool)


def fractions(terms, ident: np.ndarray, m, k_detrended: float | None = None) -> np.ndarray:
    """Mixture fractions (taus x N_CLASSES) at factors ``m`` of the quick-fit ``terms``
    (tau in sample periods) under the module's rules: the ramp's share deterministic only
    when R is identified and K is not (``ident``), else random-walk rate noise; beside such
    a ramp K at ``k_detrended`` (A_K of the detrended record, when given)."""
    a = np.array(terms, dtype=np.float64)
    deterministic = deterministic_ramp(ident)
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


def deterministic_ramp(ident: np.ndarray) -> bool:
    """Whether the ramp's share counts as deterministic, and K then comes from the
    detrended record: R identified (``ident``), K not."""
    return bool(ident[R] and not ident[K])
