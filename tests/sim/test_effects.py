"""Effects: exact values of the pure functions, and each effect simulated alone at a
known amplitude shows the ADEV/DADEV signature listed in docs/sim.md."""
from __future__ import annotations

import numpy as np
import pytest

from fogmon.davar.batch import dadev, oadev
from fogmon.davar.theory import markov_adev, sinusoid_adev
from fogmon.errors import FogmonError
from fogmon.sim import effects as fx
from fogmon.sim.model import Effect, Noise, SensorModel, validate_effect
from fogmon.sim.simulate import iter_simulate, simulate

FS = 100.0


def eff(kind, **p) -> Effect:
    return validate_effect(kind, p)


def t_grid(seconds: float, sample_rate_hz: float = FS) -> np.ndarray:
    return np.arange(int(seconds * sample_rate_hz)) / sample_rate_hz


def slope(res, lo_s, hi_s) -> float:
    """log-log slope of the ADEV between two taus."""
    sel = (res.tau_s >= lo_s) & (res.tau_s <= hi_s)
    return float(np.polyfit(np.log(res.tau_s[sel]), np.log(res.adev_dph[sel]), 1)[0])


# ---- values ---------------------------------------------------------------------------

def test_mean_effect_values():
    t = t_grid(100)
    assert np.allclose(fx.mean_rate_dph(eff("periodic", period_s=10.0, amplitude_dph=2.0, phase_rad=0.5), t, {}, FS),
                       2.0 * np.sin(2 * np.pi * t / 10 + 0.5))
    step = fx.mean_rate_dph(eff("bias_step", t_s=40.0, step_dph=-0.3), t, {}, FS)
    assert np.all(step[t < 40] == 0) and np.all(step[t >= 40] == -0.3)
    ramp = fx.mean_rate_dph(eff("rate_ramp", slope_dphh=36.0, t0_s=10.0), t, {}, FS)
    assert ramp[t == 10.0][0] == 0 and np.isclose(ramp[-1], 36.0 * (t[-1] - 10) / 3600) and np.all(ramp[t < 10] == 0)
    wu = fx.mean_rate_dph(eff("warm_up", amplitude_dph=2.0, tau_s=5.0, t0_s=20.0), t, {}, FS)
    assert np.all(wu[t < 20] == 0) and wu[t == 20][0] == 2.0 and np.isclose(wu[t == 25][0], 2.0 / np.e)


def test_glitch_lands_on_the_nearest_sample_or_spans_its_width():
    t = t_grid(10)
    g = fx.mean_rate_dph(eff("glitches", times_s=[2.004, 5.0], amplitudes_dph=[7.0, -3.0]), t, {}, FS)
    assert np.flatnonzero(g).tolist() == [200, 500] and g[200] == 7.0 and g[500] == -3.0
    w = fx.mean_rate_dph(eff("glitches", times_s=[1.0], amplitudes_dph=[1.0], width_s=0.05), t, {}, FS)
    assert np.flatnonzero(w).tolist() == [100, 101, 102, 103, 104]


def test_scale_factor_with_asymmetry_on_rot_dps():
    rot = np.array([10.0, -10.0, 0.0])
    e = eff("scale_factor", ppm=100.0, asym_ppm=20.0)
    err = fx.mean_rate_dph(e, np.arange(3.0), {"rot_dps": rot}, 1.0)
    assert np.allclose(err, [36000 * 110e-6, -36000 * 90e-6, 0.0])
    with pytest.raises(FogmonError, match="rot_dps"):
        fx.mean_rate_dph(e, np.arange(3.0), {}, 1.0)


def test_thermal_derivatives_exact_for_quadratic_temperature():
    """3-point backward differences are exact for quadratics: dT = 2 a t + b, d2T = 2 a."""
    t = t_grid(200, 10.0)
    a, b = 1e-4, 0.01
    temp = 20 + b * t + a * t ** 2
    ts, d1, d2 = fx.temperature_derivatives(t, temp, smooth_s=0.0, diff_step_s=2.0)
    k = t >= 4.0
    assert np.allclose(d1[k], 2 * a * t[k] + b, rtol=1e-9) and np.allclose(d2[k], 2 * a, rtol=1e-6)


def test_thermal_drift_branches_and_k0():
    t = t_grid(400, 10.0)
    p = dict(k0_poly_dph=[1.0, 0.1], k1_pos=40.0, k1_neg=10.0, k2_pos=0.0, k2_neg=0.0, smooth_s=0.0, diff_step_s=1.0)
    heat_acc = 20 + 1e-4 * t ** 2                      # dT > 0, d2T > 0 -> k1_pos
    heat_dec = 20 + 0.08 * t - 1e-4 * t ** 2           # dT > 0, d2T < 0 -> k1_neg
    k = t >= 2.0
    d_acc = fx.mean_rate_dph(eff("thermal_drift", **p), t, {"temp_c": heat_acc}, 10.0)
    d_dec = fx.mean_rate_dph(eff("thermal_drift", **p), t, {"temp_c": heat_dec}, 10.0)
    assert np.allclose(d_acc[k], 1.0 + 0.1 * heat_acc[k] + 40.0 * 2e-4 * t[k], rtol=1e-6)
    assert np.allclose(d_dec[k], 1.0 + 0.1 * heat_dec[k] + 10.0 * (0.08 - 2e-4 * t[k]), rtol=1e-6)


def test_thermal_drift_streamed_equals_batch():
    """The streaming simulator prepends lookback_s of history: same numbers as batch."""
    t = t_grid(600, 10.0)
    temp = 20 + 5 * np.sin(2 * np.pi * t / 300) ** 2
    m = SensorModel(10.0, 0.0, Noise(), [eff("thermal_drift", k0_poly_dph=[0.0, 0.01], k1_pos=40.0, k1_neg=20.0,
                                             k2_pos=100.0, k2_neg=50.0, smooth_s=20.0, diff_step_s=3.0)])
    batch = fx.mean_rate_dph(m.effects[0], t, {"temp_c": temp}, 10.0)
    streamed = np.concatenate([b.rate_dph for b in iter_simulate(m, aux={"temp_c": temp}, seed=1, chunk_samples=97)])
    assert np.allclose(streamed, batch, rtol=1e-9, atol=1e-9)


def test_white_level_effects():
    e = eff("vibration_noise", n_gain_dpsh_per_g=0.01)
    assert np.allclose(fx.white_level_dpsh(e, np.arange(3.0), {"vib_g": np.array([0, 1, 5.0])}), [0, 0.01, 0.05])
    e = eff("temperature_noise", n_gain_dpsh_per_c=0.001, t_ref_c=25.0)
    assert np.allclose(fx.white_level_dpsh(e, np.arange(2.0), {"temp_c": np.array([25.0, 45.0])}), [0, 0.02])


# ---- ADEV / DADEV signatures ------------------------------------------------------------

def test_periodic_signature_is_the_sinusoid_hump():
    rec = simulate(SensorModel(FS, 0.0, Noise(), [eff("periodic", period_s=20.0, amplitude_dph=1.0, phase_rad=0.3)]),
                   duration_s=4000.0, seed=1)
    res = oadev(rec.rate_dph, FS, taus=16, alpha=0)
    sel = (res.tau_s >= 0.5) & (res.tau_s <= 100)
    assert np.allclose(res.adev_dph[sel], sinusoid_adev(res.tau_s[sel], 1.0, 20.0), rtol=0.05)
    peak = res.tau_s[np.argmax(res.adev_dph)]
    assert abs(peak / 20.0 - 0.371) < 0.05 and abs(res.adev_dph.max() - 0.725) < 0.02


def test_markov_signature_peaks_at_1_89_tau_c():
    sig = []
    for s in range(6):
        rec = simulate(SensorModel(10.0, 0.0, Noise(), [eff("markov", tau_c_s=5.0, sigma_dph=2.0)]),
                       duration_s=3000.0, seed=s)
        r = oadev(rec.rate_dph, 10.0, taus=16, alpha=0)
        sig.append(r.adev_dph ** 2)
    ad = np.sqrt(np.mean(sig, 0))
    sel = (r.tau_s >= 1.0) & (r.tau_s <= 30.0)
    assert np.allclose(ad[sel], markov_adev(r.tau_s[sel], 2.0, 5.0), rtol=0.05)
    assert 6.0 < r.tau_s[np.argmax(ad)] < 13.0


def test_glitches_excess_falls_like_white_noise():
    """One spike of amplitude A in n samples: AVAR = A^2 / (m n) exactly, ADEV slope -1/2."""
    n, a = 200000, 50.0
    rec = simulate(SensorModel(FS, 0.0, Noise(), [eff("glitches", times_s=[1000.0], amplitudes_dph=[a])]),
                   duration_s=n / FS, seed=1)
    res = oadev(rec.rate_dph, FS, taus="octave", alpha=0)
    m = res.m.astype(float)
    assert np.allclose(res.adev_dph ** 2, a ** 2 / (m * (n - 2 * m + 1)), rtol=1e-6)
    assert abs(slope(res, 0.01, 10.0) + 0.5) < 0.01


def test_bias_step_excess_grows_like_sqrt_tau():
    rec = simulate(SensorModel(FS, 0.0, Noise(), [eff("bias_step", t_s=1000.0, step_dph=1.0)]),
                   duration_s=2000.0, seed=1)
    res = oadev(rec.rate_dph, FS, taus="octave", alpha=0)
    assert abs(slope(res, 0.1, 100.0) - 0.5) < 0.03


def test_rate_ramp_signature_exact():
    rec = simulate(SensorModel(FS, 0.0, Noise(), [eff("rate_ramp", slope_dphh=360.0, t0_s=0.0)]),
                   duration_s=1000.0, seed=1)
    res = oadev(rec.rate_dph, FS, taus="octave", alpha=0)
    assert np.allclose(res.adev_dph, 360.0 / 3600.0 * res.tau_s / np.sqrt(2), rtol=1e-6)


def test_warm_up_signature_is_a_transient_hump_seen_only_early():
    m = SensorModel(FS, 0.0, Noise(N_dpsh=0.001), [eff("warm_up", amplitude_dph=2.0, tau_s=60.0, t0_s=0.0)])
    rec = simulate(m, duration_s=2400.0, seed=3)
    d = dadev(rec.rate_dph, FS, window_s=600.0, hop_s=600.0, taus="octave", alpha=0)
    j = np.argmin(np.abs(d.tau_s - 40.96))
    white = 0.06 / np.sqrt(d.tau_s[j])
    assert d.adev_dph[0, j] > 10 * white and np.all(d.adev_dph[2:, j] < 1.3 * white)


@pytest.mark.parametrize("kind,aux_name,gain",
                         [("vibration_noise", "vib_g", 0.02), ("temperature_noise", "temp_c", 0.002)])
def test_level_noise_raises_white_line_where_the_aux_channel_is_high(kind, aux_name, gain):
    """N0 = 0.01 deg/sqrt(h); aux 0 in the first half, 5 (g or degC above t_ref) in the
    second: the DADEV white line moves from 0.6/sqrt(tau) to 60 (N0 + 5 gain)/sqrt(tau)."""
    n = int(2000 * FS)
    x = np.where(np.arange(n) < n // 2, 0.0, 5.0)
    params = {"n_gain_dpsh_per_g": gain} if kind == "vibration_noise" else {"n_gain_dpsh_per_c": gain, "t_ref_c": 0.0}
    rec = simulate(SensorModel(FS, 0.0, Noise(N_dpsh=0.01), [eff(kind, **params)]), aux={aux_name: x}, seed=2)
    d = dadev(rec.rate_dph, FS, window_s=500.0, hop_s=500.0, taus="octave", alpha=0)
    sel = d.tau_s <= 10.0
    ratio = d.adev_dph[:, sel] * np.sqrt(d.tau_s[sel]) / 60.0
    assert np.allclose(ratio[:2], 0.01, rtol=0.06)
    assert np.allclose(ratio[2:], 0.01 + 5 * gain, rtol=0.06)


def test_scale_factor_signature_follows_rotation():
    n = int(200 * FS)
    rot = np.where(np.arange(n) < n // 2, 20.0, -20.0)
    rec = simulate(SensorModel(FS, 1.0, Noise(N_dpsh=0.001), [eff("scale_factor", ppm=50.0, asym_ppm=10.0)]),
                   aux={"rot_dps": rot}, seed=2)
    err = rec.rate_dph - 1.0 - 3600 * rot
    assert abs(err[: n // 2].mean() - 72000 * 55e-6) < 0.02
    assert abs(err[n // 2:].mean() + 72000 * 45e-6) < 0.02


def test_bandwidth_pulls_adev_below_white_line_over_first_taus_only():
    white = Noise(N_dpsh=0.1)
    base = oadev(simulate(SensorModel(FS, 0.0, white), duration_s=2000.0, seed=4).rate_dph, FS, alpha=0)
    bw = oadev(simulate(SensorModel(FS, 0.0, white, [eff("bandwidth", cutoff_hz=5.0, order=2)]),
                        duration_s=2000.0, seed=4).rate_dph, FS, alpha=0)
    r = bw.adev_dph / base.adev_dph
    assert r[0] < 0.5 and np.all(np.abs(r[bw.tau_s >= 0.64] - 1) < 0.03)
    # FIR [0.5, 0.5]: overlapping ADEV at tau0 is exactly half the white line in expectation
    fir = oadev(simulate(SensorModel(FS, 0.0, white, [eff("bandwidth", taps=[0.5, 0.5])]),
                         duration_s=2000.0, seed=4).rate_dph, FS, alpha=0)
    assert abs(fir.adev_dph[0] / (60 * 0.1 * np.sqrt(FS)) - 0.5) < 0.01


def test_bandwidth_starts_in_steady_state():
    rec = simulate(SensorModel(FS, 5.0, Noise(), [eff("bandwidth", cutoff_hz=1.0, order=4)]), duration_s=10.0, seed=1)
    assert np.allclose(rec.rate_dph, 5.0, rtol=1e-9)


def test_thermal_drift_signature_in_dadev_follows_the_chamber_ramps():
    """k1 = 40 deg/h per degC/s on a chamber cycle (1 C/min ramps): windows holding a
    ramp corner show a large long-tau excess, windows deep in a plateau sit on the white
    line."""
    from fogmon.sim.scenarios import ChamberParams, thermal_chamber
    sc = thermal_chamber(ChamberParams(plateaus_c=(20.0, 0.0, 20.0), dwell_s=1800.0, lag1_s=20.0, lag2_s=40.0))
    m = SensorModel(10.0, 0.0, Noise(N_dpsh=0.001), [eff("thermal_drift", k0_poly_dph=[], k1_pos=40.0, k1_neg=40.0,
                                                         k2_pos=0.0, k2_neg=0.0)])
    rec = simulate(m, aux=sc.aux, aux_t_s=sc.t_s, seed=1)
    d = dadev(rec.rate_dph, 10.0, window_s=600.0, hop_s=150.0, taus="octave", alpha=0)
    j = np.argmin(np.abs(d.tau_s - 51.2))
    white = 0.06 / np.sqrt(d.tau_s[j])
    corners = np.array([1800.0, 3000.0, 4800.0, 6000.0])  # ramp starts/ends (20 min ramps)
    dist = np.min(np.abs(d.t_s[:, None] - corners[None, :]), axis=1)
    near, far = dist < 150.0, dist > 700.0
    assert near.any() and far.any()
    assert np.all(d.adev_dph[near, j] > 5 * white)
    assert np.all(d.adev_dph[far, j] < 1.3 * white)
