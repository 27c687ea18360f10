"""Issue 11 item 5: the effect kinds `noise` (the model's own IEEE-952 coefficients are
wrong) and `vibration_lines` (narrowband random vibration), simulated with known truth:
named with their numbers and intervals, written into --out-model, removable, and a
null left alone."""

import numpy as np
import pytest
from helpers.explain import explain_run
from scipy.signal import welch

from fogmon.cli import main
from fogmon.explain.analysis import whittle_context
from fogmon.explain.candidates import coefficients, lines
from fogmon.explain.explainer import stochastic_part
from fogmon.formats.replay_log import read_replay_log
from fogmon.sim.model import Effect, Noise, SensorModel, save_model
from fogmon.sim.simulate import iter_simulate, simulate

LINES = Effect("vibration_lines", {"freq_hz": [3.0, 11.0], "sigma_dph": [1.5, 1.2], "bandwidth_hz": [0.05, 0.2]})


def _covers(p: dict, name: str, truth: float) -> None:
    v, lo, hi = p[name], p[f"{name}_lo"], p[f"{name}_hi"]
    assert lo <= truth <= hi, (name, lo, truth, hi)
    assert lo <= v <= hi and abs(v - truth) <= (hi - lo) / 2, (name, v, truth, lo, hi)


def test_wrong_n_in_the_model_is_named_with_its_interval_and_written_into_noise(tmp_path):
    truth = SensorModel(10.0, 1.5, Noise(N_dpsh=0.041, B_dph=0.01))
    model = SensorModel(10.0, 1.5, Noise(N_dpsh=0.030, B_dph=0.01))
    rep, fitted, _, _ = explain_run(tmp_path, truth, model, 3600.0, seed=7)
    assert [e["kind"] for e in rep["effects"]] == ["noise"]
    p = rep["effects"][0]["params"]
    assert set(p) == {"N_dpsh", "N_dpsh_lo", "N_dpsh_hi"}          # only the term that differs
    _covers(p, "N_dpsh", 0.041)
    assert "your N is" in rep["verdict"] and "not 0.03" in rep["verdict"]
    assert fitted.effects == [] and fitted.noise.N_dpsh == pytest.approx(p["N_dpsh"])
    assert fitted.noise.B_dph == 0.01 and rep["score_after"] <= 1.5


def test_wrong_b_in_the_model_is_named_and_written_into_noise(tmp_path):
    truth = SensorModel(10.0, 0.0, Noise(N_dpsh=0.005, B_dph=0.04))
    model = SensorModel(10.0, 0.0, Noise(N_dpsh=0.005, B_dph=0.015))
    rep, fitted, _, _ = explain_run(tmp_path, truth, model, 4 * 3600.0, seed=8)
    assert [e["kind"] for e in rep["effects"]] == ["noise"]
    p = rep["effects"][0]["params"]
    _covers(p, "B_dph", 0.04)
    assert "your B is" in rep["verdict"]
    assert fitted.noise.B_dph == pytest.approx(p["B_dph"]) and fitted.effects == []


def test_two_narrowband_lines_are_fitted_and_removed(tmp_path):
    nz = Noise(N_dpsh=0.01, B_dph=0.01)
    truth = SensorModel(50.0, 1.0, nz, [LINES])
    rep, fitted, raw, cor = explain_run(tmp_path, truth, SensorModel(50.0, 1.0, nz), 1200.0, seed=9)
    assert [e["kind"] for e in rep["effects"]] == ["vibration_lines"]
    p = rep["effects"][0]["params"]
    assert len(p["freq_hz"]) == 2
    for f, s, bw, tf, ts, tb in zip(p["freq_hz"], p["sigma_dph"], p["bandwidth_hz"], *LINES.params.values(),
                                    strict=True):
        assert abs(f - tf) <= tb and s == pytest.approx(ts, rel=0.2) and bw == pytest.approx(tb, rel=0.5)
    assert [e.kind for e in fitted.effects] == ["vibration_lines"] and rep["score_after"] <= 1.5
    f, p_raw = welch(raw.rate_dph, fs=50.0, nperseg=4096)
    _, p_cor = welch(cor.rate_dph, fs=50.0, nperseg=4096)
    for tf in LINES.params["freq_hz"]:
        k = int(np.argmin(np.abs(f - tf)))
        assert p_cor[k] < 0.2 * p_raw[k]                         # the Wiener estimate removes the line


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_null_gives_neither_kind(seed):
    model = SensorModel(20.0, 0.0, Noise(Q_arcsec=0.2, N_dpsh=0.01, B_dph=0.01))
    rec = simulate(model, duration_s=1800.0, seed=seed)
    y = rec.rate_dph - rec.rate_dph.mean()
    ctx = whittle_context(stochastic_part(model), {}, rec.t_s, np.ones(len(y), bool), y)
    for fn in (coefficients.noise, lines.vibration_lines):
        c = fn(ctx)
        assert c is None or c.bic_gain(ctx.penalty) <= 0, (c.kind, c.params, c.gain)


def test_a_broad_band_like_a_microseism_is_a_line():
    """A band of Q = 1.5 (the G ring's secondary microseism: 0.214 Hz, 0.142 Hz wide) is
    fitted as a line, not dropped as broadband shape."""
    nz = Noise(N_dpsh=0.01)
    band = Effect("vibration_lines", {"freq_hz": [0.3], "sigma_dph": [1.0], "bandwidth_hz": [0.2]})
    rec = simulate(SensorModel(20.0, 0.0, nz, [band]), duration_s=1800.0, seed=4)
    y = rec.rate_dph - rec.rate_dph.mean()
    ctx = whittle_context(stochastic_part(SensorModel(20.0, 0.0, nz)), {}, rec.t_s, np.ones(len(y), bool), y)
    c = lines.vibration_lines(ctx)
    assert c is not None and c.bic_gain(ctx.penalty) > 0
    (f,), (s,), (bw,) = c.params["freq_hz"], c.params["sigma_dph"], c.params["bandwidth_hz"]
    assert abs(f - 0.3) < 0.05 and s == pytest.approx(1.0, rel=0.2) and bw == pytest.approx(0.2, rel=0.3)


def test_sim_of_a_vibration_lines_model_has_the_stated_rms_and_peak(tmp_path):
    m = SensorModel(100.0, 0.0, Noise(), [Effect("vibration_lines", {"freq_hz": [7.0], "sigma_dph": [2.0],
                                                                     "bandwidth_hz": [0.5]})])
    mp, out = tmp_path / "m.toml", tmp_path / "s.csv"
    save_model(m, mp)
    assert main(["sim", "--model", str(mp), "--out", str(out), "--duration-s", "3600", "--seed", "4"]) == 0
    r = read_replay_log(out).rate_dph
    assert np.std(r) == pytest.approx(2.0, rel=0.06)             # ~1/sqrt(bandwidth * T) = 2.4 % scatter
    f, p = welch(r, fs=100.0, nperseg=8192)
    assert abs(f[np.argmax(p)] - 7.0) <= 0.25
    half = p > p.max() / 2                                       # -3 dB width of the resonator
    assert 0.3 <= (f[half].max() - f[half].min()) <= 0.8
    a = np.concatenate([b.rate_dph for b in iter_simulate(m, duration_s=60.0, seed=4, chunk_samples=777)])
    b = np.concatenate([b.rate_dph for b in iter_simulate(m, duration_s=60.0, seed=4)])
    assert np.array_equal(a, b)                                  # one realization whatever the chunking


def test_lines_refit_a_baseline_low_pass_level_that_held_their_power():
    """A baseline without N whose white noise is a first-order low-pass (a MEMS filter)
    was fitted with the lines' power in its level (105.6 deg/h: the Allan variance at tau0
    of both): vibration_lines refits that level under the lines instead of adding their
    power a second time."""
    lowpass = Effect("markov", {"tau_c_s": 0.008, "sigma_dph": 100.0})
    line = Effect("vibration_lines", {"freq_hz": [116.0], "sigma_dph": [15.0], "bandwidth_hz": [0.1]})
    rec = simulate(SensorModel(250.0, 0.0, Noise(), [lowpass, line]), duration_s=120.0, seed=3)
    y = rec.rate_dph - rec.rate_dph.mean()
    baseline = SensorModel(250.0, 0.0, Noise(), [Effect("markov", {"tau_c_s": 0.008, "sigma_dph": 105.6})])
    ctx = whittle_context(stochastic_part(baseline), {}, rec.t_s, np.ones(len(y), bool), y)
    c = lines.vibration_lines(ctx)
    assert c is not None and c.bic_gain(ctx.penalty) > 0 and c.stoch_base is not None
    assert c.params["freq_hz"][0] == pytest.approx(116.0, abs=0.1)
    assert c.stoch_base.effects[0].params["sigma_dph"] == pytest.approx(100.0, rel=0.01)
    assert "sigma 105.6 -> " in c.evidence


def test_lines_under_a_filter_refit_n_and_q_jointly():
    """A model whose bandwidth filter joined after N and Q were split without it (the G
    ring's baseline: N too high, Q too low for its 4-pole decimation filter): vibration_lines
    refits both under the lines and the filter, near the truth."""
    bw = Effect("bandwidth", {"cutoff_hz": 8.0, "order": 4, "taps": []})
    line = Effect("vibration_lines", {"freq_hz": [3.0], "sigma_dph": [1.5], "bandwidth_hz": [0.05]})
    rec = simulate(SensorModel(20.0, 0.0, Noise(Q_arcsec=0.15, N_dpsh=0.01), [bw, line]), duration_s=1800.0, seed=5)
    y = rec.rate_dph - rec.rate_dph.mean()
    model = SensorModel(20.0, 0.0, Noise(Q_arcsec=0.105, N_dpsh=0.015), [bw])
    ctx = whittle_context(stochastic_part(model), {}, rec.t_s, np.ones(len(y), bool), y)
    c = lines.vibration_lines(ctx)
    assert c is not None and c.bic_gain(ctx.penalty) > 0 and c.stoch_base is not None
    assert min(abs(f - 3.0) for f in c.params["freq_hz"]) < 0.05 and c.k == 3 * len(c.params["freq_hz"]) + 2
    assert c.stoch_base.noise.N_dpsh == pytest.approx(0.01, rel=0.1)      # seeds 5-7: 0.0101-0.0104
    assert c.stoch_base.noise.Q_arcsec == pytest.approx(0.15, rel=0.1)    # 0.141-0.143
    assert "N 0.015 -> " in c.evidence and "Q 0.105 -> " in c.evidence
