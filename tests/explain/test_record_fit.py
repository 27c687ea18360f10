"""One fit for one record (issue 28, item 7): explain's report states the record's IEEE-952
coefficients exactly as the replay's summary prints them for the same samples."""

import numpy as np
from helpers.doubles import ListSource

from fogmon.explain.report import record_fit, record_fit_text
from fogmon.pipeline import PipelineConfig, run_pipeline
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate


def test_explain_states_the_replays_whole_record_fit():
    m = SensorModel(100.0, noise=Noise(N_dpsh=0.5), effects=[Effect("markov", {"sigma_dph": 60.0, "tau_c_s": 5.0})])
    rec = simulate(m, duration_s=5000.0, seed=5)
    n = len(rec.t_s)
    s = run_pipeline(ListSource(rec.t_s, rec.rate_dph, [n // 4] * 4, 100.0),
                     PipelineConfig(keep_motion=True, window_s=640.0), sinks=[])
    rf = record_fit(rec, keep_motion=True)
    for name, c in s.overall_fit.coefficients().items():
        got = rf[name]
        assert got["identifiable"] == bool(c.identifiable), name
        assert np.allclose([got["value"], got["lo"], got["hi"], got["upper"]],
                           [float(c.value), float(c.lo), float(c.hi), float(c.upper)], rtol=1e-12), name
    # the hump's top the fit took for a flicker floor is refused by both, with the same bound
    assert [c["name"] for c in rf["contradicted"]] == [c.name for c in s.overall_fit.contradicted] == \
        ["B_dph", "K_dphsh"]
    text = record_fit_text(rf)
    assert f"B < {rf['B_dph']['upper']:.4g} deg/h" in text and "B_dph 33.06 refuted by the ADEV" in text


def test_the_record_fit_keeps_out_what_the_replays_motion_gate_does():
    """explain cuts motion out with the offline test (bursts too); the record fit it states
    is still the replay's: the live gate's samples left out, the same coefficients."""
    m = SensorModel(100.0, noise=Noise(N_dpsh=0.05, B_dph=0.5))
    rec = simulate(m, duration_s=1200.0, seed=3)
    t = rec.t_s
    turn = (t >= 600.0) & (t < 630.0)
    rec.rate_dph[turn] += 3600.0 * 50.0 * np.sin(2 * np.pi * (t[turn] - 600.0) / 30.0)   # a hand turn, deg/h
    n = len(t)
    s = run_pipeline(ListSource(t, rec.rate_dph, [n // 4] * 4, 100.0), PipelineConfig(window_s=300.0), sinks=[])
    rf = record_fit(rec)
    assert rf["motion_samples"] == s.motion_samples > turn.sum()
    for name, c in s.overall_fit.coefficients().items():
        assert np.allclose([rf[name]["value"], rf[name]["upper"]], [float(c.value), float(c.upper)], rtol=1e-12), name
    assert "samples of platform motion kept out by its gate" in record_fit_text(rf)
