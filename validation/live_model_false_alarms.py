"""False alarms of the live model check (fogmon.modelcheck) on long null runs.

Each null is a simulated gyro that is exactly its model (the model's band part:
IEEE-952 noise, markov, bandwidth), streamed for 24 h of simulated time through the
live engines: ``iter_simulate`` -> ``StreamingDadev`` (window W, hop W/4) ->
``ModelWatch`` with the model's ``ModelBand`` (family-wise alpha per window). Every
departure is a false alarm.

Prints per model: windows, windows out of band (fraction vs alpha), departures and
departures per hour next to the stated rates (``stated_rate``: alpha x 3600 / window_s
for independent windows; at most alpha x 3600 / hop_s for any hop). PASS when, for
every model, the windows out of band and the departures per hour are within what the
stated rates allow: the count is not above its stated expectation by more than a
one-sided Poisson test at 0.1 % (scipy.stats.poisson), the windows-out count inflated
for the overlap of windows (a window out makes up to window/hop overlapping windows out).

    python validation/live_model_false_alarms.py [--hours 24] [--rate-hz 10] [--window 1024] [--seeds 1]
"""
from __future__ import annotations

import argparse
import sys
import tempfile

import numpy as np
from scipy.stats import poisson

from fogmon.davar.streaming import StreamingDadev
from fogmon.modelcheck.band import ModelBand
from fogmon.modelcheck.watch import ModelWatch, stated_rate
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import iter_simulate

MODELS = {
    "white+flicker+rrw": lambda sample_rate_hz: SensorModel(
        sample_rate_hz, 3.0, Noise(N_dpsh=0.05, B_dph=0.05, K_dphsh=0.02)
    ),
    "quantization+white+ramp": lambda sample_rate_hz: SensorModel(
        sample_rate_hz, -2.0, Noise(Q_arcsec=0.5, N_dpsh=0.02, R_dphh=0.5)
    ),
    "white+markov+bandwidth": lambda sample_rate_hz: SensorModel(
        sample_rate_hz,
        0.0,
        Noise(N_dpsh=0.05, B_dph=0.02),
        [
            Effect("markov", {"tau_c_s": 20.0, "sigma_dph": 0.3}),
            Effect("bandwidth", {"cutoff_hz": 0.3 * sample_rate_hz, "order": 2}),
        ],
    ),
}
P_FAIL = 1e-3


def null_run(model: SensorModel, hours: float, window_n: int, seed: int, alpha: float,
             replicates: int, cache_dir: str) -> tuple[dict, dict]:
    """Stream ``hours`` h of the model through StreamingDadev + ModelWatch; returns
    (watch summary, stated rates)."""
    sample_rate_hz = model.sample_rate_hz
    # alpha=0: fixed noise type for the (unused) confidence bounds; the ADEV is the same
    sd = StreamingDadev(sample_rate_hz, window_n / sample_rate_hz, hop_s=window_n / 4 / sample_rate_hz, alpha=0)
    band = ModelBand.for_model(model, sample_rate_hz, window_n, sd.m, alpha=alpha, replicates=replicates,
                               seed=10_000 + seed, cache_dir=cache_dir)
    watch = ModelWatch(band, ())
    for blk in iter_simulate(model, duration_s=hours * 3600.0, seed=seed):
        r = sd.push(blk)
        for i in range(len(r)):
            watch.frame((r.end_index[i] + 1) / sample_rate_hz, r.adev_dph[i], {})
    return watch.summary(), stated_rate(band, sd.hop_n / sample_rate_hz)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=24.0, help="simulated time per null run (h)")
    ap.add_argument("--rate-hz", dest="sample_rate_hz", type=float, default=10.0, help="sample rate (Hz)")
    ap.add_argument("--window", type=int, default=1024, help="DADEV window (samples); hop = window / 4")
    ap.add_argument("--alpha", type=float, default=0.01, help="family-wise false-alarm rate per window")
    ap.add_argument("--replicates", type=int, default=None, help="bootstrap windows (default: the library's)")
    ap.add_argument("--seeds", type=int, default=1, help="null runs per model")
    a = ap.parse_args(argv)
    kw = {} if a.replicates is None else {"replicates": a.replicates}
    ok = True
    with tempfile.TemporaryDirectory() as cache_dir:
        for name, make in MODELS.items():
            for seed in range(a.seeds):
                s, st = null_run(make(a.sample_rate_hz), a.hours, a.window, seed, a.alpha,
                                 kw.get("replicates", 100), cache_dir)
                hours = (s["time_inside_s"] + s["time_outside_s"]) / 3600.0
                hop_per_window = 4
                exp_out = a.alpha * s["windows"]
                # windows out: overlapping windows share data; the count's variance is up to
                # window/hop times the Poisson one, so the test uses clusters of that size
                p_out = poisson.sf(np.ceil(s["windows_out"] / hop_per_window) - 1, exp_out / hop_per_window)
                exp_dep = st["per_hour_max"] * hours
                p_dep = poisson.sf(s["n_departures"] - 1, exp_dep)
                good = p_out > P_FAIL and p_dep > P_FAIL
                ok &= good
                print(f"{name:26s} seed {seed}: {s['windows']:5d} windows, {s['windows_out']:4d} out "
                      f"(fraction {s['windows_out'] / max(s['windows'], 1):.4f} vs alpha {a.alpha:g}), "
                      f"{s['n_departures']:3d} departures = {s['n_departures'] / hours:.3f}/h "
                      f"(stated: {st['per_hour_independent']:.3f}/h independent windows, "
                      f"<= {st['per_hour_max']:.3f}/h), threshold |z| {s['threshold_abs_z']:.3f}  "
                      f"{'PASS' if good else 'FAIL'}", flush=True)
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
