"""Coverage of `fogmon thermal`'s intervals (fogmon.methods.thermal, docs/methods.md):
chamber runs simulated from a model with known thermal coefficients, calibrated the way
`fogmon thermal RECORDING` does (filters chosen by the fit, standard errors under the
residual's own noise), over many seeds.

Run:  python validation/thermal_coverage.py [--seeds 50] [--model replay_logs/sim_thermal_chamber.toml]
Prints, per coefficient, the mean estimate, the scatter over the seeds, the mean stated
standard error, and the share of 68 % (+-1 sigma) and 95 % (+-1.96 sigma) intervals that
cover the truth; how often the fit chose the model's own difference step; the old method
(fixed 10 s / 1 s filters, white-noise errors) beside it. PASS when every 95 % coverage is
at least 90 % (binomial scatter of 50 seeds at 95 %: 3 %).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from fogmon.methods.thermal import calibrate_thermal
from fogmon.sim.model import load_model
from fogmon.sim.scenarios import make_scenario
from fogmon.sim.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]
NAMES = ("k1_pos", "k1_neg", "k2_pos", "k2_neg")
MIN_COVERAGE_95 = 0.90


def _old_white_errors(rec, degree: int) -> dict:
    """The method before issue 31: filters 10 s / 1 s, white-noise least-squares errors."""
    from fogmon.methods.thermal import _design, _lstsq
    from fogmon.sim.effects import temperature_derivatives

    t, y, T = rec.t_s, rec.rate_dph, rec.aux["temp_c"]
    X = _design(*temperature_derivatives(t, T, 10.0, 1.0), degree)
    use = t >= t[0] + 12.0
    scale, live, b, W, resid = _lstsq(X[use], y[use])
    s2 = float(resid @ resid) / (len(resid) - len(b))
    beta, se = np.zeros(X.shape[1]), np.full(X.shape[1], np.inf)
    beta[live], se[live] = b / scale[live], np.sqrt(s2 * np.sum(W * W, axis=1)) / scale[live]
    return {n: (beta[degree + 1 + i], se[degree + 1 + i]) for i, n in enumerate(NAMES)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--model", default=str(ROOT / "replay_logs/sim_thermal_chamber.toml"))
    a = ap.parse_args(argv)
    model = load_model(a.model)
    truth = next(e.params for e in model.effects if e.kind == "thermal_drift")
    sc = make_scenario("chamber", {}, None, 0)
    new: dict[str, list] = {n: [] for n in NAMES}
    old: dict[str, list] = {n: [] for n in NAMES}
    same_step = 0
    for seed in range(a.seeds):
        rec = simulate(model, aux=sc.aux, aux_t_s=sc.t_s, seed=1000 + seed)
        cal = calibrate_thermal(rec.t_s, rec.rate_dph, rec.aux["temp_c"], degree=len(truth["k0_poly_dph"]) - 1)
        same_step += cal.effect.params["diff_step_s"] == truth["diff_step_s"]
        for n in NAMES:
            new[n].append((cal.effect.params[n], cal.stderr[n]))
        for n, v in _old_white_errors(rec, len(truth["k0_poly_dph"]) - 1).items():
            old[n].append(v)
    print(f"{a.seeds} chamber runs of {Path(a.model).name} ({model.sample_rate_hz:g} Hz, {sc.t_s[-1]:g} s; "
          f"truth smooth_s {truth['smooth_s']:g} s, diff_step_s {truth['diff_step_s']:g} s): the fit chose "
          f"diff_step_s {truth['diff_step_s']:g} s in {same_step} of {a.seeds}")
    ok = True
    for label, res in (("fogmon thermal", new), ("old: 10 s / 1 s, white errors", old)):
        print(f"{label}:")
        for n in NAMES:
            v, se = np.array(res[n]).T
            z = np.abs(v - truth[n]) / se
            c68, c95 = float(np.mean(z <= 1.0)), float(np.mean(z <= 1.96))
            print(f"  {n:<7} truth {truth[n]:<7g} mean {v.mean():<9.4g} scatter {v.std(ddof=1):<8.3g} "
                  f"mean stated se {se.mean():<8.3g} covered: 68 % intervals {100 * c68:3.0f} %, "
                  f"95 % intervals {100 * c95:3.0f} %")
            if res is new:
                ok &= c95 >= MIN_COVERAGE_95
    print("PASS" if ok else f"FAIL: a 95 % coverage below {100 * MIN_COVERAGE_95:.0f} %")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
