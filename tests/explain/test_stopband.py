"""Issue 11: against the exact true model with a 4-pole low-pass, explain finds nothing
missing: its Whittle likelihoods are taken over the filter's pass band (no periodic term
in the stop band, a score at chance)."""
import numpy as np
import pytest
from helpers.explain import explain_run

from fogmon.explain.analysis import whittle_context
from fogmon.explain.candidates.base import in_passband
from fogmon.explain.explainer import stochastic_part
from fogmon.explain.fitting import rfft_omega
from fogmon.explain.mismatch import CHANCE_SCORE
from fogmon.explain.selection import candidates
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate

TRUTH = SensorModel(20.0, 0.0, Noise(N_dpsh=0.01), [Effect("bandwidth", {"cutoff_hz": 8.0, "order": 4, "taps": []})])


def test_the_candidates_see_only_the_pass_band():
    # the record of the finding: a periodic term at 9.24 Hz (|H|^2 1e-3) had gain 160
    rec = simulate(TRUTH, duration_s=1800.0, seed=4)
    y = rec.rate_dph - rec.rate_dph.mean()
    ctx = whittle_context(stochastic_part(TRUTH), {}, rec.t_s, np.ones(len(y), bool), y)
    stop = ~in_passband(TRUTH, rfft_omega(ctx.n))
    assert stop.any() and np.all(ctx.wh.w[stop] == 0.0)
    cands = candidates(ctx, {})
    assert all(c.bic_gain(ctx.penalty) <= 0 for c in cands)
    assert all(np.isfinite(c.gain) for c in cands)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_explain_adds_nothing_against_the_true_filtered_model(tmp_path, seed):
    # 20 null records of 600 s: score_before 0.89..1.22 (median 1.0); 1.5 is the chance bar
    rep, fitted, _, _ = explain_run(tmp_path, TRUTH, TRUTH, 600.0, seed=seed)
    assert rep["effects"] == [] and fitted == TRUTH
    assert rep["score_after"] <= CHANCE_SCORE
