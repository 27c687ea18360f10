"""Issue 11: a Gauss-Markov term under the sensor's own low-pass (a `bandwidth` filter
in the model): its candidate is fitted over the filter's pass band, so its gain is
finite, and it is recovered with known truth; the score's `tests` leave out the kinds
the map contradicted."""
import math
import warnings

import numpy as np
import pytest
from helpers.explain import explain_run

from fogmon.explain.analysis import matched_tests_figure, whittle_context
from fogmon.explain.candidates import spectral
from fogmon.explain.candidates.base import Candidate
from fogmon.explain.explainer import stochastic_part
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate

FILTER = Effect("bandwidth", {"cutoff_hz": 8.0, "order": 4, "taps": []})
MARKOV = Effect("markov", {"tau_c_s": 5.0, "sigma_dph": 1.0})
NOISE = Noise(N_dpsh=0.01)


def test_markov_candidate_under_a_filter_is_finite_and_recovers_the_truth():
    truth = SensorModel(20.0, 0.0, NOISE, [FILTER, MARKOV])
    rec = simulate(truth, duration_s=1800.0, seed=3)
    model = stochastic_part(SensorModel(20.0, 0.0, NOISE, [FILTER]))
    y = rec.rate_dph - rec.rate_dph.mean()
    ctx = whittle_context(model, {}, rec.t_s, np.ones(len(y), bool), y)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no division by the filter's zeros
        c = spectral.markov(ctx)
    assert c is not None and math.isfinite(c.gain) and c.gain > 100 * ctx.penalty
    assert c.params["sigma_dph"] == pytest.approx(1.0, rel=0.2)
    assert c.params["tau_c_s"] == pytest.approx(5.0, rel=0.4)
    assert "pass band" in c.evidence


def test_explain_adds_the_markov_term_under_the_filter(tmp_path):
    truth = SensorModel(20.0, 0.0, NOISE, [FILTER, MARKOV])
    rep, fitted, _, _ = explain_run(tmp_path, truth, SensorModel(20.0, 0.0, NOISE, [FILTER]), 1800.0, seed=5)
    assert [e["kind"] for e in rep["effects"]] == ["markov"]
    p = rep["effects"][0]["params"]
    assert p["sigma_dph"] == pytest.approx(1.0, rel=0.2) and p["tau_c_s"] == pytest.approx(5.0, rel=0.4)
    assert [e.kind for e in fitted.effects] == ["bandwidth", "markov"] and rep["score_after"] <= 1.5


def test_matched_tests_figure_leaves_out_contradicted_kinds():
    big = Candidate("markov", {}, {}, gain=1.6e5, k=2, evidence="")
    small = Candidate("bandwidth", {}, {}, gain=400.0, k=2, evidence="")
    pen = math.log(216000)
    assert matched_tests_figure([big, small], pen, set()) == pytest.approx(math.sqrt(1.6e5 / (2 * pen)))
    assert matched_tests_figure([big, small], pen, {"markov"}) == pytest.approx(math.sqrt(400.0 / (2 * pen)))
    assert matched_tests_figure([big], pen, {"markov"}) == 0.0
