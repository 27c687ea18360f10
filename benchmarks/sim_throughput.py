"""Simulator throughput and memory for long runs (streaming, nothing written).

Streams ``--hours`` of a full model (Q, N, B, K + markov + vibration/thermal/scale-factor
effects driven by an MWD scenario) at ``--rate-hz`` through ``iter_simulate`` and prints
samples/s, the ratio to plain numpy white-noise generation measured in the same run,
and the peak resident memory (which must not grow with the duration).

    python benchmarks/sim_throughput.py --hours 1 --rate-hz 1000
    python benchmarks/sim_throughput.py --hours 24 --rate-hz 1000   # ~3 min
"""
from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.scenarios import MwdParams, mwd_run
from fogmon.sim.simulate import iter_simulate


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--rate-hz", dest="sample_rate_hz", type=float, default=1000.0)
    a = ap.parse_args()
    dur = a.hours * 3600.0
    model = SensorModel(a.sample_rate_hz, 0.1, Noise(0.01, 0.02, 0.05, 0.01, 0.0), [
        Effect("thermal_drift", {"k0_poly_dph": [0.0, 0.002], "k1_pos": 40.0, "k1_neg": 25.0,
                                 "k2_pos": 0.0, "k2_neg": 0.0}),
        Effect("vibration_noise", {"n_gain_dpsh_per_g": 0.005}),
        Effect("scale_factor", {"ppm": 30.0, "asym_ppm": 5.0}),
        Effect("markov", {"tau_c_s": 60.0, "sigma_dph": 0.02}),
    ])
    sc = mwd_run(MwdParams(duration_s=dur), seed=1)
    base = rss_mb()
    t0 = time.perf_counter()
    n = 0
    for b in iter_simulate(model, aux=sc.aux, aux_t_s=sc.t_s, seed=1):
        n += len(b)
    dt = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    t1 = time.perf_counter()
    for _ in range(20):
        rng.standard_normal(1 << 20)
    ref = 20 * (1 << 20) / (time.perf_counter() - t1)
    print(f"{n} samples ({dur:g} s at {a.sample_rate_hz:g} Hz) in {dt:.1f} s: {n / dt / 1e6:.2f} M samples/s "
          f"= 1/{ref / (n / dt):.0f} of numpy normal generation ({ref / 1e6:.0f} M/s)")
    print(f"peak RSS {rss_mb():.0f} MB (after building the scenario: {base:.0f} MB; "
          f"a whole-record float64 array would be {n * 8 / 1e6:.0f} MB)")


if __name__ == "__main__":
    main()
