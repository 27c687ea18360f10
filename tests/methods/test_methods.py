"""Paper methods against known truth: thermal calibration recovers the coefficients and
shrinks drift; Pauta/differencing recovers ARW despite an orbit term and glitches;
Kalman filters reach their Riccati error variance; up/down calibration is exact."""
import math

import numpy as np
import pytest

from fogmon.methods import denoise, earthrate, inorbit, thermal
from fogmon.sim.effects import thermal_drift
from fogmon.sim.scenarios import ChamberParams, thermal_chamber


def test_thermal_calibration_recovers_coefficients_and_cuts_drift():
    sc = thermal_chamber(ChamberParams(plateaus_c=(20.0, -40.0, 60.0, 20.0), dwell_s=1800.0))
    t, T = sc.t_s, sc.aux["temp_c"]
    truth = {"k0_poly_dph": [0.3, 0.004, 5e-5], "k1_pos": 40.0, "k1_neg": 25.0, "k2_pos": 3000.0,
             "k2_neg": -2000.0, "smooth_s": 10.0, "diff_step_s": 1.0}
    drift = thermal_drift(t, {"temp_c": T}, truth)
    rng = np.random.default_rng(3)
    rate = drift + rng.normal(0.0, 0.05, len(t))  # white noise 0.05 deg/h per 1 s sample
    cal = thermal.calibrate_thermal(t, rate, T)
    p = cal.effect.params
    np.testing.assert_allclose(p["k0_poly_dph"], truth["k0_poly_dph"], rtol=0.05)
    for k in ("k1_pos", "k1_neg"):
        assert abs(p[k] - truth[k]) < 4 * cal.stderr[k] + 0.02 * abs(truth[k])
    corrected = thermal.correct_thermal(t, rate, T, cal.effect)
    before = thermal.drift_peak_to_peak(t, rate, 100.0)
    after = thermal.drift_peak_to_peak(t, corrected, 100.0)
    assert before > 1.0 and after < before / 5.0
    assert abs(cal.residual_std_dph - 0.05) < 0.005


@pytest.mark.parametrize("k", [2.5, 3.0])
def test_pauta_consistency_factor_matches_monte_carlo(k):
    x = np.random.default_rng(5).normal(0.0, 1.0, 400_000)
    kept = x[inorbit.pauta_mask(x, k)]
    assert kept.std() == pytest.approx(inorbit.pauta_consistency(k), rel=3e-3)


def test_arw_from_differences_ignores_orbit_term_and_glitches():
    sample_rate_hz, n_dpsh = 10.0, 0.02
    n = 6 * 55800  # six 5580 s orbits at 10 Hz
    t = np.arange(n) / sample_rate_hz
    rng = np.random.default_rng(7)
    sigma = 60 * n_dpsh * math.sqrt(sample_rate_hz)
    rate = rng.normal(0.0, sigma, n) + 5.0 * np.sin(2 * np.pi * t / inorbit.ORBIT_PERIOD_S)
    spikes = rng.choice(n, 400, replace=False)
    rate[spikes] += rng.choice([-1, 1], 400) * 30 * sigma
    est = inorbit.arw_from_differences(rate, sample_rate_hz)
    assert est.N_dpsh == pytest.approx(n_dpsh, rel=0.01)
    assert est.outliers >= 400
    naive = np.diff(rate).std() / math.sqrt(2) / (60 * math.sqrt(sample_rate_hz))
    assert naive > 1.3 * n_dpsh  # the glitches would have ruined the plain estimate


def test_cycle_bias_instability_is_std_of_cycle_means():
    period, sample_rate_hz = 100.0, 2.0
    means = np.array([1.0, 3.0, 2.0, 5.0])
    t = np.arange(int(4.5 * period * sample_rate_hz)) / sample_rate_hz
    rate = np.repeat(np.append(means, 9.0), int(period * sample_rate_hz))[: len(t)]
    bi, ncyc = inorbit.cycle_bias_instability(t, rate, period)
    assert ncyc == 4 and bi == pytest.approx(means.std(ddof=1))


def test_wavelet_energy_locates_a_sinusoid():
    sample_rate_hz = 100.0
    t = np.arange(2 ** 14) / sample_rate_hz
    bands = inorbit.wavelet_energy(np.sin(2 * np.pi * 4.5 * t), sample_rate_hz)
    lo, hi, e = max(bands, key=lambda b: b[2])
    assert lo <= 4.5 <= hi and e > 0.6
    assert sum(b[2] for b in bands) == pytest.approx(1.0)


def test_static_kalman_error_variance_matches_riccati():
    sample_rate_hz, N, K = 100.0, 0.01, 2.0
    n = 400_000
    rng = np.random.default_rng(11)
    truth = np.cumsum(rng.normal(0, (K / 60) / math.sqrt(sample_rate_hz), n)) + 3.0
    z = truth + rng.normal(0, 60 * N * math.sqrt(sample_rate_hz), n)
    est = denoise.kalman_static(z, sample_rate_hz, N, K)
    _, p_post = denoise.static_gain(sample_rate_hz, N, K)
    mse = np.mean((est[20_000:] - truth[20_000:]) ** 2)
    assert mse == pytest.approx(p_post, rel=0.06)
    assert mse < 0.05 * np.var(z - truth)


def test_dynamic_kalman_error_variance_matches_riccati():
    sample_rate_hz, N, qa = 100.0, 0.01, 5.0
    n = 400_000
    dt = 1 / sample_rate_hz
    rng = np.random.default_rng(13)
    F = np.array([[1, dt], [0, 1]])
    Q = qa ** 2 * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    w = rng.multivariate_normal([0, 0], Q, n)
    x = np.zeros((n, 2))
    for k in range(1, n):  # reference simulation of the state model
        x[k] = F @ x[k - 1] + w[k]
    z = x[:, 0] + rng.normal(0, 60 * N * math.sqrt(sample_rate_hz), n)
    est = denoise.kalman_dynamic(z, sample_rate_hz, N, qa)
    L = denoise.dynamic_gain(sample_rate_hz, N, qa)
    from scipy.linalg import solve_discrete_are
    P = solve_discrete_are(F.T, np.array([[1.0], [0.0]]), Q, np.array([[(60 * N) ** 2 * sample_rate_hz]]))
    p_post = ((np.eye(2) - np.outer(L, [1, 0])) @ P)[0, 0]
    mse = np.mean((est[20_000:] - x[20_000:, 0]) ** 2)
    assert mse == pytest.approx(p_post, rel=0.06)


def test_wavelet_denoise_reduces_error_of_a_smooth_signal():
    t = np.arange(2 ** 14) / 100.0
    clean = 5 * np.sin(2 * np.pi * 0.05 * t)
    noisy = clean + np.random.default_rng(2).normal(0, 1.0, len(t))
    out = denoise.wavelet_denoise(noisy)
    assert np.sqrt(np.mean((out - clean) ** 2)) < 0.35  # per-sample noise is 1.0


def test_updown_calibration_is_exact():
    lat, b, sf = 34.246, 0.7, 150e-6
    v = earthrate.EARTH_RATE_DPH * math.sin(math.radians(lat))
    up, down = b + (1 + sf) * v, b - (1 + sf) * v
    r = earthrate.updown_calibration(up, down, lat)
    assert r["bias_dph"] == pytest.approx(b) and r["scale_factor_ppm"] == pytest.approx(150.0)


def test_static_kalman_stream_equals_the_batch_filter_and_holds_over_gaps():
    rng = np.random.default_rng(4)
    z = rng.normal(5.0, 10.0, 50_000)
    batch = denoise.kalman_static(z, 100.0, 0.1, 0.05)
    stream = denoise.StaticKalmanStream(100.0, 0.1, 0.05)
    cuts = np.cumsum(rng.integers(1, 3000, 40))
    out = np.concatenate([stream.push(p) for p in np.split(z, cuts[cuts < len(z)])])
    assert np.max(np.abs(out - batch)) < 1e-9 * np.max(np.abs(batch))
    gap = z[:100].copy()
    gap[40:60] = np.nan
    held = denoise.StaticKalmanStream(100.0, 0.1, 0.05).push(gap)
    assert np.all(held[40:60] == held[39]) and np.isfinite(held).all()
