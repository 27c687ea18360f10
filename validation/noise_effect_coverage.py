"""Coverage of the `noise` effect's 95 % intervals (docs/explain.md): simulated records
whose model states the wrong N, corrected by fogmon.explain.candidates.coefficients.fit_coefficients.

Run:  python validation/noise_effect_coverage.py [--records 40] [--duration-s 3600]
Prints the mean estimate, its scatter over the records, the mean stated standard error
and the share of 95 % intervals that cover the true N.
"""
from __future__ import annotations

import argparse

import numpy as np

from fogmon.explain.candidates.coefficients import fit_coefficients
from fogmon.sim.model import Noise, SensorModel
from fogmon.sim.simulate import simulate

FS_HZ = 10.0
TRUE_N, MODEL_N, B = 0.041, 0.030, 0.01


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=40)
    ap.add_argument("--duration-s", type=float, default=3600.0)
    a = ap.parse_args(argv)
    truth = SensorModel(FS_HZ, 0.0, Noise(N_dpsh=TRUE_N, B_dph=B))
    model = SensorModel(FS_HZ, 0.0, Noise(N_dpsh=MODEL_N, B_dph=B))
    est, se, cover = [], [], 0
    for i in range(a.records):
        r = simulate(truth, duration_s=a.duration_s, seed=100 + i).rate_dph
        y = r - r.mean()
        v, lo, hi, _ = fit_coefficients(y, np.ones(len(y), bool), model, FS_HZ, MODEL_N)["N_dpsh"]
        est.append(v)
        se.append((hi - lo) / 3.92)
        cover += lo <= TRUE_N <= hi
    print(f"{a.records} records of {a.duration_s:g} s at {FS_HZ:g} Hz, true N {TRUE_N} deg/sqrt(h), model N {MODEL_N}: "
          f"mean estimate {np.mean(est):.5f}, scatter {np.std(est, ddof=1):.2e}, mean stated se "
          f"{np.mean(se):.2e}, 95 % intervals covering the truth {100 * cover / a.records:.0f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
