"""Coverage of explain's standard errors of the mean-type effects (issue 28; docs/explain.md,
"Standard errors under long memory"): records simulated from issue 28's five-term model
(Q 0.1 arcsec, N 0.01 deg/sqrt(h), B 0.3 deg/h, K 3 deg/h/sqrt(h), R 5 deg/h/h at 100 Hz,
2^17 samples = 22 min) with one effect of known size added, explained against the
five-term model without it (the command's defaults: ``without_motion`` then
``explain``). For every record that names the effect, each stated parameter's error is
compared with the truth: z = (estimate - truth) / error; the table prints how often
|z| < 1 (nominal 68.3 %) and |z| < 1.96 (95 %), and z's mean and sd over the records.
Record i of effect e is simulated with seed (--seed) x 1,000,003 + 1000 e + i.

PASS when every parameter's 95 % coverage lies within two binomial standard errors of
95 % (or within 93-97 %).

    python validation/effect_coverage.py [--records 40] [--jobs 2] [--seed 1] [--only bias_step]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from multiprocessing import Pool

import numpy as np

from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate

FS_HZ = 100.0
SAMPLES = 2 ** 17
BACKGROUND = Noise(0.1, 0.01, 0.3, 3.0, 5.0)
#: each effect well above its detection limit on this background (a per-sample white
#: noise of 6 deg/h, a random walk of ~1.8 deg/h over the record)
EFFECTS = {
    "periodic": Effect("periodic", {"period_s": 60.0, "amplitude_dph": 1.0, "phase_rad": 1.0}),
    "bias_step": Effect("bias_step", {"t_s": 500.0, "step_dph": 6.0}),
    "rate_ramp": Effect("rate_ramp", {"slope_dphh": 60.0, "t0_s": 600.0}),
    "warm_up": Effect("warm_up", {"amplitude_dph": 8.0, "tau_s": 100.0, "t0_s": 0.0}),
}


def one(job: tuple[str, int, int]) -> tuple[str, dict | None, list[str], float]:
    """(effect, {param: z} when named, other kinds named, CPU s) of record ``job`` = (effect, i, seed)."""
    from fogmon.explain.explainer import explain, without_motion
    from fogmon.explain.options import Options

    kind, i, seed = job
    effect = EFFECTS[kind]
    t0 = time.process_time()
    truth = SensorModel(FS_HZ, noise=BACKGROUND, effects=[effect])
    rec = simulate(truth, duration_s=SAMPLES / FS_HZ, seed=seed * 1_000_003 + 1000 * list(EFFECTS).index(kind) + i)
    rec, _ = without_motion(rec)
    res = explain(rec, SensorModel(FS_HZ, noise=BACKGROUND), Options(workers=1))
    named = [a.cand for a in res.accepted if a.cand.kind == kind]
    others = [a.cand.kind for a in res.accepted if a.cand.kind != kind]
    z = None
    if named:
        c = named[0]
        z = {}
        for p, true in effect.params.items():
            se = c.se.get(p)
            if se is None or not (np.isfinite(se) and se > 0):
                continue
            d = c.params[p] - true
            z[p] = (math.remainder(d, 2 * math.pi) if p == "phase_rad" else d) / se
    return kind, z, others, time.process_time() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=40, help="records per effect")
    ap.add_argument("--jobs", type=int, default=2, help="records explained at once")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--only", action="append", choices=list(EFFECTS), help="this effect only (repeatable)")
    a = ap.parse_args()
    kinds = a.only or list(EFFECTS)
    jobs = [(k, i, a.seed) for i in range(a.records) for k in kinds]
    with Pool(a.jobs) as pool:
        rows = pool.map(one, jobs, chunksize=1)
    print(f"explain --model <five-term background> on records with one effect (seed {a.seed}): "
          f"|z| = |estimate - truth| / stated error")
    print(f"  {'effect':10s} {'param':14s} {'named':>7s} {'|z|<1':>7s} {'|z|<1.96':>9s} "
          f"{'mean z':>7s} {'sd z':>6s}  verdict")
    ok = True
    for k in kinds:
        mine = [r for r in rows if r[0] == k]
        zs = [r[1] for r in mine if r[1] is not None]
        others = sorted({o for r in mine for o in r[2]})
        for p in EFFECTS[k].params:
            z = np.array([d[p] for d in zs if p in d])
            if not len(z):
                continue
            c1, c2 = float(np.mean(np.abs(z) < 1.0)), float(np.mean(np.abs(z) < 1.959964))
            band = 2.0 * math.sqrt(0.95 * 0.05 / len(z))
            good = abs(c2 - 0.95) <= max(band, 0.02)
            ok &= good
            print(f"  {k:10s} {p:14s} {len(zs):3d}/{len(mine):<3d} {100 * c1:6.1f}% {100 * c2:8.1f}% "
                  f"{z.mean():+7.2f} {z.std():6.2f}  {'PASS' if good else 'FAIL'}")
        if others:
            print(f"  {k:10s} other kinds named beside it: {', '.join(others)}")
    print(f"{np.mean([r[3] for r in rows]):.1f} CPU s a record; 95 % coverage within two binomial "
          f"standard errors of 95 %: {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
