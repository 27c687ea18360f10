"""False alarms of the console's model check (fogmon.davar.adequacy) on exact records.

Each record is fogmon's own simulator (fogmon.sim) of an IEEE-952 noise model and
nothing else, fitted as `fogmon replay` fits the whole run (``davar.record.whole_record_fit``)
and checked as the console checks it (``adequacy.check_model``), so every warning is a
false alarm. The check states a family-wise level of MODEL_CHECK_LEVEL (1 %) per curve.

The models: the calibration's (validation/calibration.py, MODELS and HELD_OUT: all five
terms in the mix, 1 Hz to 1 kHz) and a ramp-dominated one (N 0.01 deg/sqrt(h), B 0.02
deg/h, R 20 deg/h^2 at 10 Hz), where the ADEV takes the ramp as deterministic (EDF
~1e5-1e6 at the longest taus) and the check once warned on 3 % of records.

Prints per model: records warned and records whose ADEV took the ramp as deterministic
(``AdevResult.ramp_k``). PASS when no model warns on more than the level plus two
binomial standard deviations of its records.

    python validation/model_check_false_alarms.py [--records 200] [--jobs 2] [--seed 1] [--models NAME,...]
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from multiprocessing import Pool

import numpy as np

from fogmon.davar.adequacy import MODEL_CHECK_LEVEL, check_model
from fogmon.davar.record import whole_record_fit
from fogmon.sim.model import Noise
from fogmon.sim.simulate import simulate

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from calibration import HELD_OUT, MODELS, Case, record_seed  # noqa: E402  (the calibration's models)

RAMP = Case("NBR_10Hz_1.8h_R20", Noise(0.0, 0.01, 0.02, 0.0, 20.0), 10.0, 16)
CASES = (RAMP, *MODELS, *HELD_OUT)


def _one(job: tuple[Case, int]) -> tuple[bool, bool]:
    """(warned, ramp deterministic) of one exact record."""
    case, seed = job
    rate = simulate(case.model, duration_s=case.duration_s, seed=seed).rate_dph
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a motion-gate note on an exact record is motion_false_alarms.py's business
        adev, fit = whole_record_fit(rate, None, case.sample_rate_hz)
    check = check_model(adev, fit)
    return check is not None and check.departs, bool(np.isfinite(adev.ramp_k))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=200, help="records per model")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--models", help="comma-separated model names (default: all)")
    args = ap.parse_args(argv)
    cases = CASES
    if args.models:
        names = args.models.split(",")
        unknown = set(names) - {c.name for c in CASES}
        if unknown:
            ap.error(f"unknown model(s) {', '.join(sorted(unknown))}; known: {', '.join(c.name for c in CASES)}")
        cases = tuple(c for c in CASES if c.name in names)
    t0 = time.time()
    jobs = [(c, record_seed(args.seed, i)) for c in cases for i in range(args.records)]
    with Pool(args.jobs) as pool:
        out = pool.map(_one, jobs, chunksize=2)
    limit = MODEL_CHECK_LEVEL + 2.0 * np.sqrt(MODEL_CHECK_LEVEL * (1 - MODEL_CHECK_LEVEL) / args.records)
    print(f"Model check on {args.records} exact records per model (seed {args.seed}); stated level "
          f"{100 * MODEL_CHECK_LEVEL:g} %, limit {100 * limit:.1f} % (level + 2 sd)")
    print(f"  {'model':<22} {'warned':>12} {'ramp deterministic':>19}")
    ok = True
    for j, case in enumerate(cases):
        mine = np.array(out[j * args.records:(j + 1) * args.records])
        warned = int(mine[:, 0].sum())
        good = warned / args.records <= limit
        ok &= good
        print(f"  {case.name:<22} {warned:4d} ({100 * warned / args.records:4.1f} %) {int(mine[:, 1].sum()):19d}  "
              f"{'PASS' if good else 'FAIL'}")
    print(f"{'PASS' if ok else 'FAIL'} ({time.time() - t0:.0f} s)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
