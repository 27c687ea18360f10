"""Rules for the mixture behind the EDF of the longest taus, compared on calibration records.

The per-tau ADEV intervals (``validation/calibration.py``, "Per-tau ADEV intervals") take
their EDF from the noise mixture of a quick IEEE-952 fit (``fogmon.davar.record_mixture``). At the
longest taus that mixture decides the interval and is poorly known: a chance ramp where
there is none (NBK) makes the interval too narrow, a chance random walk K beside a real
ramp (NBR) too wide. This script scores alternative mixtures on the calibration's own
records (same models, same seeds) so that a rule is measured before it enters the
product. Not part of any verdict; docs/davar.md ("Calibration") quotes its tables.

Rules (each with the chi-square shape, and with ``S`` the exact shape of
``fogmon.davar.shape`` at the taus where it applies):

- ``quick``: the quick fit's own mixture (``fit.quick_avar_terms``; the product's before
  ``fogmon.davar.record_mixture``).
- ``ramp_id``: the ramp's share deterministic only when the whole-run fit
  (``fit_noise``) identifies R, else counted as random-walk rate noise.
- ``detrended``: ``ramp_id`` with K taken from the quick fit of the record with its
  least-squares line removed (a ramp has no Allan variance there; a random walk keeps
  most of its own: K's estimate no longer trades against R's).
- ``detr_exact``: ``detrended`` with the expected Allan variance of detrended white-rate
  and random-walk noise in that fit (``detrend_factors``: at m = n / 4 a detrended random
  walk keeps 0.47 of its Allan variance).
- ``hybrid``: the product's (``fogmon.davar.record_mixture``): the ramp's share
  deterministic only where the fit rejects R = 0 at ``DETERMINISTIC_Z`` and does not
  identify K, and then K the detrended record's quick-fit estimate (identified or not);
  else counted as random-walk rate noise.
- ``true``: the simulator's model (the reference).

    python validation/edf_rules.py [--records 200] [--models 2,3,4] [--last 6] [--seed 1] [--jobs 2]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from scipy.stats import chi2

from fogmon.davar import record_mixture
from fogmon.davar.batch import oadev
from fogmon.davar.confidence import edf_mixture_from, mixture_matrices, term_fractions
from fogmon.davar.fit import _NoiseModel, _scoring, fit_noise, low_pass_taus, octave_subset, quick_avar_terms
from fogmon.davar.shape import shape_factors
from fogmon.davar.theory import NAMES, POWERS, avar_terms_to_coefficients, coefficients_to_avar_terms
from fogmon.modelcheck.band import theory_adev_dph

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from calibration import CONFIDENCES, MODELS, _map, _record, record_seed  # noqa: E402

RULES = ("quick", "ramp_id", "detrended", "detr_exact", "hybrid", "true")
K, R = 3, 4  # Q, N, B, K, R: the classes' order (confidence.MIX_ALPHAS, then the ramp)


def _ramp_random(f: np.ndarray) -> np.ndarray:
    f = f.copy()
    f[:, K] += f[:, R]
    f[:, R] = 0.0
    return f


def _quick(res, n: int) -> np.ndarray:
    return quick_avar_terms(res.tau_s, res.adev_dph**2, res.m, res.n_terms, n)


def _product(res, res_detr, a: np.ndarray, n: int, sample_rate_hz: float) -> np.ndarray:
    """The product's mixture (``record_mixture``'s rules) at ``res.tau_s`` (s) of the quick-fit ``a``."""
    deterministic = record_mixture.deterministic_ramp(
        record_mixture.record_fit(res.tau_s, res.adev_dph**2, res.m, res.n_terms, n))
    # detrended_k's A_K is per sample period (tau in samples); a's tau is in s
    k = (record_mixture.detrended_k(res_detr.adev_dph**2, res_detr.m, res_detr.n_terms, n)
         * sample_rate_hz) if deterministic else None
    return record_mixture.fractions(a, deterministic, res.tau_s, k)


def detrend_factors(m, n: int) -> np.ndarray:
    """(len(m), 2): E[Allan variance of n samples minus their least-squares line] / E[Allan
    variance] at factors m, for white rate noise and for random-walk rate noise. Exact:
    the line's slope b and the terms' signed mean are linear in the samples, the terms
    shift by -b m^2, so the ratio needs E[b mean(d)] and E[b^2] (O(n) per m)."""
    i = np.arange(n, dtype=np.float64)
    w = (i - i.mean()) / np.sum((i - i.mean()) ** 2)  # slope = w . y
    w_tail = np.cumsum(w[::-1])[::-1]  # a random walk's covariance min(i, l) + 1 as sums over steps
    out = np.empty((len(m), 2))
    for k, mm in enumerate(np.asarray(m, dtype=np.int64)):
        n_terms = n - 2 * mm + 1
        late = np.clip(np.minimum(n_terms - 1, i - mm) - np.maximum(0, i - 2 * mm + 1) + 1, 0, None)
        early = np.clip(np.minimum(n_terms - 1, i) - np.maximum(0, i - mm + 1) + 1, 0, None)
        v = (late - early) / n_terms  # mean of the terms = v . y
        m2 = float(mm) ** 2
        raw = 2.0 * mm  # white rate: E[mean d^2] of unit variance
        out[k, 0] = (raw - 2 * m2 * (w @ v) + m2 * m2 * (w @ w)) / raw
        v_tail = np.cumsum(v[::-1])[::-1]
        raw = 2 * m2 * (2 * m2 + 1) / (6 * mm)  # random walk of unit steps
        out[k, 1] = (raw - 2 * m2 * (w_tail @ v_tail) + m2 * m2 * (w_tail @ w_tail)) / raw
    return out


def _detrended_k(res_detr, n: int) -> float:
    """A_K of the quick fit's method on the Allan variance of the detrended record with
    the expected Allan variance of detrended white-rate and random-walk noise (their
    columns scaled by ``detrend_factors``), no ramp."""
    tau, avar, m, n_terms = res_detr.tau_s, res_detr.adev_dph**2, res_detr.m, res_detr.n_terms
    use = np.flatnonzero((n_terms > 0) & np.isfinite(avar) & (avar > 0))
    use = use[octave_subset(m[use], n // 4)]
    use = use[low_pass_taus(avar[use]):]
    if len(use) < 2:
        return 0.0
    x = tau[use][:, None] ** POWERS
    g = detrend_factors(m[use], n)
    x[:, 1] *= g[:, 0]
    x[:, K] *= g[:, 1]
    cols = np.array([True, True, True, True, False])
    return float(_scoring(x, cols, avar[use], _NoiseModel(tau[use], m[use], n_terms[use], n), np.ones(len(use)),
                          rtol=1e-3)[0][K])


def record_rules(job: tuple[int, int, int]) -> tuple[int, np.ndarray, dict, np.ndarray]:
    """(model index, tau_s, {rule: coverage (2 confidences x taus)}, [K identified, K of
    the quick fit, K detrended (deg/h/sqrt(h))]) of one record."""
    k, i, seed = job
    case = MODELS[k]
    rec = _record(case, record_seed(seed, i))
    n = len(rec.rate_dph)
    res = oadev(rec.rate_dph, case.sample_rate_hz, taus="octave")
    truth = theory_adev_dph(case.model, res.m, case.sample_rate_hz, case.duration_s)
    tau, m = res.tau_s, res.m
    fit = fit_noise(res)
    ident = np.array([bool(getattr(fit, name).identifiable) for name in NAMES])
    r_ident = bool(ident[R])
    a = _quick(res, n)
    t_s = np.arange(n) / case.sample_rate_hz
    line = np.polyval(np.polyfit(t_s, rec.rate_dph, 1), t_s)
    res_detr = oadev(rec.rate_dph - line, case.sample_rate_hz, taus="octave")
    a_detr, a_exact = a.copy(), a.copy()
    a_detr[K] = _quick(res_detr, n)[K]
    a_exact[K] = _detrended_k(res_detr, n)
    ramp_rule = (lambda f: f) if r_ident else _ramp_random
    mix = {"quick": term_fractions(a, tau), "ramp_id": ramp_rule(term_fractions(a, tau)),
           "detrended": ramp_rule(term_fractions(a_detr, tau)), "detr_exact": ramp_rule(term_fractions(a_exact, tau)),
           "hybrid": _product(res, res_detr, a, n, case.sample_rate_hz),
           "true": term_fractions(coefficients_to_avar_terms(*case.truth), tau)}
    mats, full = mixture_matrices(m, n), n - 2 * m + 1
    out = {}
    for rule, f in mix.items():
        edf = edf_mixture_from(f, mats, full)
        for shaped in (False, True):
            cover = []
            for c in CONFIDENCES:
                lo = res.adev_dph * np.sqrt(edf / chi2.ppf(0.5 + c / 2, edf))
                hi = res.adev_dph * np.sqrt(edf / chi2.ppf(0.5 - c / 2, edf))
                if shaped:
                    f_lo, f_hi = shape_factors(f, m, n, edf, c)
                    ok = np.isfinite(f_lo) & np.isfinite(f_hi)
                    lo, hi = np.where(ok, res.adev_dph * f_lo, lo), np.where(ok, res.adev_dph * f_hi, hi)
                cover.append((lo <= truth) & (truth <= hi))
            out[rule + ("S" if shaped else "")] = np.array(cover)
    k_dphsh = avar_terms_to_coefficients(np.array([a, a_detr, a_exact]))[:, K]
    return k, tau, out, np.array([float(fit.K_dphsh.identifiable), *k_dphsh])


def _median(x: np.ndarray) -> str:
    return f"{np.median(x):.3g}" if len(x) else "-"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--records", type=int, default=200, help="records per model")
    p.add_argument("--models", default="0,1,2,3,4", help="indices into calibration.MODELS")
    p.add_argument("--last", type=int, default=6, help="how many of the longest taus to print")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--jobs", type=int, default=2)
    args = p.parse_args(argv)
    ks = [int(s) for s in args.models.split(",")]
    jobs = [(k, i, args.seed) for k in ks for i in range(args.records)]
    rows = _map(record_rules, jobs, args.jobs)
    print(f"Coverage (%) of the per-tau ADEV intervals at 68.3 / 95 % by EDF rule, {args.records} records per "
          f"model, seed {args.seed} (S: the exact shape where it applies)")
    names = [r + s for r in RULES for s in ("", "S")]
    for k in ks:
        mine = [r for r in rows if r[0] == k]
        tau = mine[0][1]
        ks_ = np.array([r[3] for r in mine])
        ident = ks_[:, 0] > 0
        print(f"\n{MODELS[k].name} (true K {MODELS[k].noise.K_dphsh:g} deg/h/sqrt(h)): K identified in "
              f"{100 * ident.mean():.0f} %; K > 0 in the quick fit {100 * (ks_[:, 1] > 0).mean():.0f} %, detrended "
              f"{100 * (ks_[:, 2] > 0).mean():.0f} %, detr_exact {100 * (ks_[:, 3] > 0).mean():.0f} %; median K "
              f"quick / detrended / detr_exact where identified {_median(ks_[ident, 1])} / {_median(ks_[ident, 2])} / "
              f"{_median(ks_[ident, 3])}, where not {_median(ks_[~ident, 1])} / {_median(ks_[~ident, 2])} / "
              f"{_median(ks_[~ident, 3])} ({(~ident).sum()} records)")
        print(f"  {'tau_s':>7s}" + "".join(f"{nm:>13s}" for nm in names))
        cover = {nm: 100.0 * np.mean([r[2][nm] for r in mine], axis=0) for nm in names}
        for j in range(max(len(tau) - args.last, 0), len(tau)):
            print(f"  {tau[j]:7.4g}" + "".join(f"  {cover[nm][0, j]:5.1f}/{cover[nm][1, j]:4.1f}" for nm in names))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
