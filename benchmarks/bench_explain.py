"""Runtime of `fogmon explain` on a 1e6-sample recording (target <= 60 s on 2 cores).

Prints the wall time of the whole analysis (bootstrap, map, candidate selection, map
again) for a null recording and one with a concealed periodic term, and, as a
reference measured in the same run, the time of one simulation + one DADEV of the
same length (the bootstrap's unit of work), so the ratio travels across machines.

Run:  python benchmarks/bench_explain.py [--n 1000000]
"""
from __future__ import annotations

import argparse
import math
import time

from fogmon.davar.batch import dadev
from fogmon.explain.explainer import explain
from fogmon.explain.options import Options
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="samples (at 100 Hz)")
    a = ap.parse_args()
    sample_rate_hz = 100.0
    noise = Noise(Q_arcsec=0.05, N_dpsh=0.01, B_dph=0.01)
    base = SensorModel(sample_rate_hz, 0.5, noise, [])
    sigma = math.sqrt((60 * 0.01) ** 2 * sample_rate_hz + 2 * (0.05 * sample_rate_hz) ** 2)
    t0 = time.perf_counter()
    rec0 = simulate(base, duration_s=a.n / sample_rate_hz, seed=1)
    dadev(rec0.rate_dph, sample_rate_hz, window_s=a.n / sample_rate_hz / 8, alpha=0)
    unit = time.perf_counter() - t0
    print(f"reference: one simulation + one DADEV of {a.n} samples: {unit:.2f} s")
    for label, eff in (("null", []),
                       ("periodic 0.3 sigma", [Effect("periodic", {"period_s": 777.0, "amplitude_dph": 0.3 * sigma,
                                                                    "phase_rad": 0.0})])):
        rec = simulate(SensorModel(sample_rate_hz, 0.5, noise, eff), duration_s=a.n / sample_rate_hz, seed=2)
        t0 = time.perf_counter()
        res = explain(rec, base, Options())
        dt = time.perf_counter() - t0
        found = ", ".join(x.cand.kind for x in res.accepted) or "none"
        print(f"{label:20s} n={len(rec)} bootstrap={res.n_boot} explain: {dt:6.1f} s = {dt / unit:5.1f} x reference; "
              f"found: {found}; score {res.before.score.value:.2f} -> {res.after.score.value:.2f}; "
              f"{'PASS' if dt <= 60 else 'FAIL'} (<= 60 s)")


if __name__ == "__main__":
    main()
