"""Tails of the score test's statistic at the true coefficient, on calibration records.

The coefficients' limits (``fogmon.davar.fit.fit_curve``, ``profile.score_limits``) are
where the test's calibrated statistic z(c) of A_n = c reaches normal quantiles: the 95 %
upper limit where z = -1.645, the two-sided 95 % interval where z = -1.96 and +1.96. They
cover at their level when z at the TRUE value is standard normal. This script reads z
at the truth for every term present in each record of ``calibration.MODELS`` (same
models, same seeds): ``score_limits`` over a grid of quantiles (0.05 .. 4 in steps of
0.05, both sides), z(truth) the grid's last quantile whose limit the truth passes
(resolution 0.05, towards 0). It prints, per model and term, the tail probabilities
beside the normal's and z's mean, standard deviation and skewness (a standard normal's:
0, 1, 0), for all records and split by whether the record identifies the term. Not
part of any verdict; docs/davar.md ("Calibration") quotes it.

    python validation/score_tails.py [--records 300] [--models 0,1] [--seed 1] [--jobs 2]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from fogmon.davar import fit as F
from fogmon.davar.batch import oadev
from fogmon.davar.profile import fit_full, score_limits
from fogmon.davar.theory import NAMES, POWERS, coefficients_to_avar_terms

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from calibration import MODELS, _map, _record, record_seed  # noqa: E402

Z_GRID = np.round(np.arange(0.05, 4.0 + 1e-9, 0.05), 2)
TAILS = ((-1.96, "z<=-1.96", 0.025), (-1.645, "z<=-1.645", 0.05), (1.645, "z>=1.645", 0.05),
         (1.96, "z>=1.96", 0.025))


def record_z(job: tuple[int, int, int]) -> tuple[int, np.ndarray, np.ndarray]:
    """(model index, identified mask (5,), z at the true A_n (5,), NaN for terms absent)
    of record ``job`` = (model, i, seed), fitted as ``fit_curve`` fits the whole-run ADEV."""
    k, i, seed = job
    case = MODELS[k]
    rec = _record(case, record_seed(seed, i))
    res = oadev(rec.rate_dph, case.sample_rate_hz, taus="octave", alpha=0)  # the ADEV values only
    tau, avar, m, nt, n = res.tau_s, res.adev_dph**2, res.m, res.n_terms, res.n_samples
    ok = (nt > 0) & np.isfinite(avar) & (avar > 0)
    use = np.flatnonzero(ok)
    use = use[F.octave_subset(m[use], n // 4)]
    model = F._NoiseModel(tau[use], m[use].astype(np.int64), nt[use], n)
    x, y = tau[use][:, None] ** POWERS, avar[use]
    found, a, se, rw, c2 = fit_full(x, y, model.mats, model.full, model.gap_scale, model.cov,
                                    np.array(F._starts(len(y))), F.TUKEY_C, F.MISFIT_FLOOR**2, F.BIRGE_GATE,
                                    F._RW_TOL, F._MAX_ROBUST_ITER, F._ROBUST_RTOL, F._RTOL, F._MAX_ITER)
    s0, lower, upper = score_limits(x, y, model.mats, model.full, model.gap_scale, model.cov, rw, c2, a, se,
                                    np.ones(5, dtype=bool), F.IDENTIFY_Z, Z_GRID.copy(), Z_GRID.copy(),
                                    F._ROBUST_RTOL, F._MAX_ITER)
    truth = coefficients_to_avar_terms(*case.truth)
    z = np.full(5, np.nan)
    for j in np.flatnonzero(truth > 0):
        if truth[j] >= a[j]:  # z(truth) <= 0: the upper limits at or below the truth
            passed = Z_GRID[upper[j] <= truth[j]]
            z[j] = -passed.max() if len(passed) else 0.0
        else:
            passed = Z_GRID[lower[j] >= truth[j]]
            z[j] = passed.max() if len(passed) else 0.0
    return k, s0 > F.IDENTIFY_Z, z


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--records", type=int, default=300, help="records per model (default 300)")
    p.add_argument("--models", default=",".join(str(k) for k in range(len(MODELS))),
                   help="indices into calibration.MODELS (default all)")
    p.add_argument("--seed", type=int, default=1, help="seed of the records (default 1)")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    args = p.parse_args(argv)
    models = [int(k) for k in args.models.split(",")]
    t0 = time.time()
    jobs = [(k, i, args.seed) for k in models for i in range(args.records)]
    rows = _map(record_z, jobs, args.jobs)
    print(f"The score test's z at the true coefficient, {args.records} records per model (seed {args.seed}); "
          f"a standard normal has {', '.join(f'P({name}) {100 * q:.1f} %' for _, name, q in TAILS)}")
    print(f"  {'model':<18} {'coef':<9} {'records':<15} {'n':>5} " + " ".join(f"{name:>10}" for _, name, _ in TAILS)
          + f" {'mean':>6} {'sd':>5} {'skew':>5}")
    for k in models:
        mine = [r for r in rows if r[0] == k]
        ident = np.array([r[1] for r in mine])
        z = np.array([r[2] for r in mine])
        for j in np.flatnonzero(np.isfinite(z[0])):
            split = 0 < ident[:, j].sum() < len(z)  # else "all" is the one group
            for label, sel in (("all", np.ones(len(z), bool)), ("identified", ident[:, j]),
                               ("not identified", ~ident[:, j]))[:3 if split else 1]:
                v = z[sel, j]
                cells = " ".join(f"{100 * np.mean(v <= t if t < 0 else v >= t):9.1f}%" for t, _, _ in TAILS)
                sd = v.std()
                skew = np.mean((v - v.mean()) ** 3) / sd**3 if sd > 0 else np.nan
                print(f"  {MODELS[k].name:<18} {NAMES[j]:<9} {label:<15} {sel.sum():5d} {cells}"
                      f" {v.mean():6.2f} {sd:5.2f} {skew:5.2f}")
    print(f"({time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
