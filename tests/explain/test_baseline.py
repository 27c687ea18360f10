"""Baseline model (no --model): the relative-ADEV NNLS fit against known simulated
coefficients, and `fogmon explain` without a model on a stationary record."""
import json

import numpy as np
import pytest

from fogmon.cli import main
from fogmon.davar.theory import adev_model, markov_adev
from fogmon.explain.baseline import (
    _floor_violated,
    baseline_model,
    baseline_models,
    curve_noise_fit,
    markov_unit_avar,
    parsimonious_fit,
    robust_avar,
)
from fogmon.explain.explainer import Options, explain_without_model
from fogmon.explain.report import baseline_low_pass
from fogmon.formats.replay_log import write_replay_log
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.noise import lowpass_adev_exact
from fogmon.sim.simulate import simulate


def test_curve_fit_recovers_exact_ieee952_curve():
    tau = 2.0 ** np.arange(-6, 12)
    truth = dict(Q_arcsec=0.3, N_dpsh=0.01, B_dph=0.05, K_dphsh=0.5, R_dphh=2.0)
    fit = curve_noise_fit(tau, adev_model(tau, **truth))
    for k, v in truth.items():
        assert fit[k] == pytest.approx(v, rel=1e-6)


def test_baseline_of_a_simulated_record_has_its_q_and_n():
    m = SensorModel(100.0, 3.0, Noise(Q_arcsec=0.3, N_dpsh=0.01), [])
    b = baseline_model(simulate(m, duration_s=1800.0, seed=4))
    assert b.noise.Q_arcsec == pytest.approx(0.3, rel=0.1)   # equal weight per octave, not minimum variance
    assert b.noise.N_dpsh == pytest.approx(0.01, rel=0.15)  # Q dominates every tau up to ~1 s here
    assert b.bias_dph == pytest.approx(3.0, abs=0.5) and b.effects == []


def test_explain_without_model_on_stationary_noise_finds_nothing(tmp_path):
    rec = simulate(SensorModel(10.0, 0.0, Noise(N_dpsh=0.01, Q_arcsec=0.05), []), duration_s=3600.0, seed=8)
    p = tmp_path / "r.csv"
    write_replay_log(p, rec.t_s, rec.rate_dph, {}, {"sample_rate_hz": "10"})
    assert main(["explain", str(p), "--report", str(tmp_path / "r.json"), "--bootstrap", "30", "--quiet"]) == 0
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["model"].startswith("baseline") and rep["effects"] == [] and rep["mismatches"] == []
    assert rep["baseline_model"]["N_dpsh"] == pytest.approx(0.01, rel=0.15)


def test_markov_unit_avar_is_the_sampled_gauss_markov_allan_variance():
    tau = 2.0 ** np.arange(0, 12) / 100.0
    # a correlation time of many samples, averaging over 8 and more samples: the
    # continuous-time formula (IEEE-952 C.4; point samples differ from it at a few samples)
    assert markov_unit_avar(tau[3:], 100.0, 2.0) == pytest.approx(markov_adev(tau[3:], 1.0, 2.0) ** 2, rel=0.01)
    # one sample: (y1 - y0)^2 / 2 = 1 - a
    assert markov_unit_avar(tau[:1], 100.0, 2.0)[0] == pytest.approx(1.0 - np.exp(-1.0 / 200.0), rel=1e-9)
    # a correlation time far below a sample: white noise of unit variance, 1/m
    assert markov_unit_avar(tau, 100.0, 1e-4) == pytest.approx(1.0 / (tau * 100.0), rel=1e-9)


def test_baseline_fits_the_sensor_low_pass_instead_of_flicker():
    """White noise through a first-order low-pass (a MEMS gyro's filter, corner 30 Hz at
    250 Hz): the ADEV bends below the white slope at the shortest taus. The baseline
    names the filtered white noise (its correlation time and level) and invents no
    flicker from the bend."""
    tau_c = 1.0 / (2.0 * np.pi * 30.0)
    m = SensorModel(250.0, 0.0, Noise(N_dpsh=0.01), [Effect("markov", {"tau_c_s": tau_c, "sigma_dph": 130.0})])
    b = baseline_model(simulate(m, duration_s=120.0, seed=3))
    assert [e.kind for e in b.effects] == ["markov"]
    assert b.effects[0].params["tau_c_s"] == pytest.approx(tau_c, rel=0.1)
    assert b.effects[0].params["sigma_dph"] == pytest.approx(130.0, rel=0.05)
    assert b.noise.B_dph == 0.0 and b.noise.K_dphsh == 0.0


def test_baseline_fits_a_sharper_low_pass_beside_an_unfiltered_white_floor():
    """White noise through a 2-pole Butterworth at 40 Hz beside unfiltered white noise (a
    floor near Nyquist, as the PX4 MEMS record has) at 250 Hz: the baseline holds a
    ``lowpass_noise`` term of order above 1 near 40 Hz and N as the floor, not a
    first-order Gauss-Markov term."""
    truth = Effect("lowpass_noise", {"cutoff_hz": 40.0, "order": 2, "sigma_dph": 110.0})
    b = baseline_model(simulate(SensorModel(250.0, 0.0, Noise(N_dpsh=0.08), [truth]), duration_s=120.0, seed=4))
    assert [e.kind for e in b.effects] == ["lowpass_noise"]
    assert b.effects[0].params["order"] >= 2
    assert b.effects[0].params["cutoff_hz"] == pytest.approx(40.0, rel=0.1)
    assert b.effects[0].params["sigma_dph"] == pytest.approx(110.0, rel=0.05)
    assert b.noise.N_dpsh == pytest.approx(0.08, rel=0.1)
    assert b.noise.B_dph == 0.0 and b.noise.K_dphsh == 0.0
    lp = baseline_low_pass(b)
    assert lp["kind"] == "lowpass_noise" and lp["corner_hz"] == b.effects[0].params["cutoff_hz"]
    # the white level at long taus: the filtered part's (sigma^2 tau0 / sum h^2 = (60 N)^2) and the floor's
    m = np.array([4096])
    avar = (lowpass_adev_exact(m, b.effects[0].params["sigma_dph"], lp["corner_hz"], lp["order"], 250.0) ** 2
            + (60.0 * b.noise.N_dpsh) ** 2 * 250.0 / m)
    assert lp["white_N_dpsh"] == pytest.approx(60.0 ** -1 * np.sqrt(avar[0] * m[0] / 250.0), rel=1e-3)


def test_a_filter_over_quantization_noise_is_left_to_the_bandwidth_effect():
    """Q and N through a 4-pole decimation filter at 8.25 Hz of 20 Hz (the G ring's): a
    Butterworth on the white noise beside an unfiltered Q would lower the baseline's
    criterion (883 -> 681 with order 4, seed 1) while describing a filter that leaves the
    quantization noise alone, so the Butterworth shapes are fitted without Q and the
    filter is left to explain's ``bandwidth`` effect, over the whole rate."""
    m = SensorModel(20.0, 0.0, Noise(Q_arcsec=1e-6, N_dpsh=4e-8),
                    [Effect("bandwidth", {"cutoff_hz": 8.25, "order": 4, "taps": []})])
    b = baseline_model(simulate(m, duration_s=900.0, seed=1))
    assert b.effects == [] and b.noise.Q_arcsec > 0


def test_baseline_stays_below_a_recording_whose_short_taus_hold_sway_and_a_high_band():
    """White noise N 0.02 deg/sqrt(h) beside a sway band at 3 Hz and a broad band at 35 Hz
    (no IEEE-952 term follows either): the window-median fit takes N 0.038, above the
    recording at the long taus by more than chance; refitted below it, N is the truth's."""
    lines = [Effect("vibration_lines", {"freq_hz": [3.0], "sigma_dph": [25.0], "bandwidth_hz": [1.5]}),
             Effect("vibration_lines", {"freq_hz": [35.0], "sigma_dph": [40.0], "bandwidth_hz": [25.0]})]
    rec = simulate(SensorModel(100.0, 0.0, Noise(N_dpsh=0.02), lines), duration_s=1800.0, seed=3)
    blk = rec.to_block()
    tau, av, edf = robust_avar(blk.error_rate_dph, blk.valid, 100.0)
    first, _, low_pass = parsimonious_fit(tau, av, edf, 100.0)
    assert low_pass is None and first["N_dpsh"] > 0.03 and _floor_violated(tau, av, edf, first, None, 100.0)
    assert baseline_model(rec).noise.N_dpsh == pytest.approx(0.02, rel=0.15)


# issue 28's five-term model without its ramp: a rate random walk K = 3 deg/h/sqrt(h) over
# 22 min, which the windows' taus (up to 41 s) barely see but the whole record's long taus do
_WALK = SensorModel(100.0, 0.0, Noise(Q_arcsec=0.1, N_dpsh=0.01, B_dph=0.3, K_dphsh=3.0), [])


def test_the_long_taus_offer_a_rate_random_walk_the_windows_cannot_see():
    for s in range(3):
        base, walk = baseline_models(simulate(_WALK, duration_s=1310.72, seed=s))
        assert base.noise.K_dphsh == 0.0 and walk is not None
        assert 1.0 < walk.noise.K_dphsh < 6.0  # 2.27, 2.02, 1.33
        assert walk.noise.N_dpsh == pytest.approx(base.noise.N_dpsh, rel=0.05)


def test_no_walk_is_offered_for_a_step_the_windows_refuse():
    m = SensorModel(10.0, 0.0, Noise(N_dpsh=0.02), [Effect("bias_step", {"t_s": 3000.0, "step_dph": 0.1})])
    for s in range(3):  # the step raises the long taus as a walk would; the windows' medians refuse that walk
        assert baseline_models(simulate(m, duration_s=6553.0, seed=s))[1] is None


def test_explain_without_model_names_no_ramp_in_a_rate_random_walk():
    rec = simulate(_WALK, duration_s=1310.72, seed=7 * 1_000_003 + 7)  # named a rate_ramp before
    res = explain_without_model(rec, Options(workers=1))
    assert res.accepted == [] and res.model.noise.K_dphsh > 0
    assert [w["kind"] for w in res.warnings] == ["lookalike"] and "rate ramp" in res.warnings[0]["text"]


def test_a_step_a_walk_could_make_is_reported_as_a_lookalike():
    m = SensorModel(10.0, 0.0, Noise(N_dpsh=0.02), [Effect("bias_step", {"t_s": 3000.0, "step_dph": 0.3})])
    res = explain_without_model(simulate(m, duration_s=6553.6, seed=0), Options(workers=1))
    assert res.accepted == [] and res.model.noise.K_dphsh > 0  # K 0.18 from the long taus
    assert [w["kind"] for w in res.warnings] == ["lookalike"] and "bias step" in res.warnings[0]["text"]
