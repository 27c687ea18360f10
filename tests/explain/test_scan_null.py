"""Issue 28.1: under a model with a rate random walk (K), the mean-type candidates' bars
come from the model's own simulations (explain.scan_null), so a chance step or ramp of
the walk is not named; without K nothing is simulated."""
import numpy as np

from fogmon.explain import mismatch
from fogmon.explain.analysis import whittle_context
from fogmon.explain.bootstrap import bootstrap
from fogmon.explain.explainer import explain, stochastic_part
from fogmon.explain.options import Options
from fogmon.explain.replicas import Replicas
from fogmon.explain.scan_null import calibrated_kinds
from fogmon.explain.selection import candidates
from fogmon.sim.model import EFFECT_KINDS, Noise, SensorModel
from fogmon.sim.simulate import simulate

FS = 10.0
N = 4096
WALK = SensorModel(FS, 0.0, Noise(N_dpsh=0.02, B_dph=0.1, K_dphsh=2.0))


def test_only_a_model_with_k_calibrates_the_mean_type_kinds():
    assert calibrated_kinds(SensorModel(FS, 0.0, Noise(N_dpsh=0.02, B_dph=0.1))) == ()
    kinds = calibrated_kinds(WALK)
    assert "bias_step" in kinds and "rate_ramp" in kinds
    assert all(EFFECT_KINDS[k].nature == "mean" for k in kinds)


def test_the_walk_raises_the_bars_of_steps_and_ramps_above_bic():
    t = np.arange(N) / FS
    valid = np.ones(N, bool)
    null = bootstrap(Replicas(WALK, t, {}, valid), mismatch.make_grid(N, FS), 20, 3, 0.01, 1)
    rec = simulate(WALK, duration_s=N / FS, seed=5)
    y = rec.rate_dph - rec.rate_dph.mean()
    ctx = whittle_context(stochastic_part(WALK), {}, t, valid, y)
    by_kind = {c.kind: c for c in candidates(ctx, {}, null.scan_bars)}
    for kind in ("bias_step", "rate_ramp"):
        assert null.scan_bars[kind] > by_kind[kind].k * ctx.penalty
        assert by_kind[kind].search_bar == null.scan_bars[kind]


def test_a_null_walk_names_nothing():
    # without the simulated bars this record names a bias step (BIC's bar alone)
    rec = simulate(WALK, duration_s=N / FS, seed=0)
    res = explain(rec, WALK, Options(n_boot=20, workers=1))
    assert res.accepted == []
