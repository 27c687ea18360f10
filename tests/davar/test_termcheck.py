"""The whole-record fit checked against the measured ADEV (fogmon.davar.termcheck): no
identified term above the record's ADEV; a 1/tau slope that does not reach the shortest
tau is white angle noise, not quantization (issue 28, items 7 and 8)."""

import re

import numpy as np
import pytest

from fogmon.davar.record import whole_record_fit
from fogmon.davar.termcheck import contradictions, first_peak
from fogmon.davar.theory import coefficients_to_avar_terms
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate
from fogmon.sinks.console import coefficient_lines, contradiction_lines

TAU = np.array([1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0])
EDF = np.full(len(TAU), 20.0)


def test_a_floor_above_the_measured_adev_is_contradicted_and_bounded():
    adev = np.array([10.0, 8.0, 6.0, 5.0, 4.0, 3.0, 2.0])
    a = coefficients_to_avar_terms(B_dph=5.0 / 0.664)      # a floor of 5 deg/h, the ADEV falls to 2
    (c,) = contradictions(TAU, adev, EDF, a)
    assert c.name == "B_dph" and c.tau_s == 64.0 and c.term_adev_dph == pytest.approx(5.0, rel=1e-3)
    assert c.adev_dph == 2.0 and 2.0 < c.bound_dph < 5.0
    assert c.limit == pytest.approx(c.bound_dph / 0.6643, rel=1e-3)   # the ADEV's bound on B
    # each tau's bound at 1 - 5 % / 7, so all seven hold at 95 %: the limit is a 95 % upper limit
    assert c.bound_confidence == pytest.approx(1 - 0.05 / 7) and c.limit_confidence == pytest.approx(0.95)
    (c,) = contradictions(TAU, adev, EDF, a, level=0.01)
    assert c.limit_confidence == pytest.approx(0.99)


def test_a_floor_under_the_measured_adev_is_not_contradicted():
    adev = np.array([10.0, 8.0, 6.0, 5.0, 4.0, 3.0, 2.0])
    assert contradictions(TAU, adev, EDF, coefficients_to_avar_terms(B_dph=2.0 / 0.664)) == []
    # the bound is an upper confidence bound: a floor a little above a low-EDF point is chance
    assert contradictions(TAU, adev, np.full(len(TAU), 3.0), coefficients_to_avar_terms(B_dph=2.5 / 0.664)) == []


def test_a_floor_is_not_judged_below_a_low_pass_rising_adev():
    # the ADEV rises from the shortest tau (a low-pass): the floor is judged from its peak on
    adev = np.array([0.1, 0.4, 1.5, 3.3, 3.3, 3.2, 3.3])
    assert contradictions(TAU, adev, EDF, coefficients_to_avar_terms(B_dph=3.3 / 0.664)) == []
    # from the peak on it still is
    adev = np.array([0.1, 0.4, 1.5, 3.3, 3.3, 3.2, 0.5])
    (c,) = contradictions(TAU, adev, EDF, coefficients_to_avar_terms(B_dph=3.3 / 0.664))
    assert c.tau_s == 64.0


def test_a_filtered_flicker_floor_stays_identified():
    m = SensorModel(100.0, noise=Noise(N_dpsh=0.01, B_dph=5.0), effects=[Effect("bandwidth", {"cutoff_hz": 1.0,
                                                                                              "order": 4})])
    adev, fit = whole_record_fit(simulate(m, duration_s=3000.0, seed=1).rate_dph, None, 100.0)
    assert adev.adev_dph[0] < 0.1 * 0.664 * 5.0          # the filter: far below the floor at 0.01 s
    assert fit.B_dph.identifiable and fit.contradicted == ()


def test_n_is_not_judged():
    adev = np.full(len(TAU), 0.1)
    assert contradictions(TAU, adev, EDF, coefficients_to_avar_terms(N_dpsh=1.0)) == []


def _fit(effects, seed=3):
    rec = simulate(SensorModel(100.0, noise=Noise(Q_arcsec=1.0, N_dpsh=0.01), effects=effects),
                   duration_s=600.0, seed=seed)
    return whole_record_fit(rec.rate_dph, None, 100.0)[1]


def test_a_quantized_output_keeps_its_quantization_name():
    fit = _fit([])
    assert fit.Q_arcsec.identifiable and not fit.q_band_limited and fit.contradicted == ()
    assert "not quantization" not in "\n".join(coefficient_lines(fit))


def test_a_filtered_output_has_white_angle_noise_not_quantization():
    fit = _fit([Effect("bandwidth", {"cutoff_hz": 5.0, "order": 2})])
    assert fit.Q_arcsec.identifiable and fit.q_band_limited
    lines = "\n".join(coefficient_lines(fit) + contradiction_lines(fit))
    assert "white angle noise, not quantization" in lines and "does not reach the shortest taus" in lines
    # the bound on an output quantizer states its level
    assert re.search(r"family-wise 5 % over the taus\).*an output quantizer is < \S+ arcsec \(95 % upper limit\)$",
                     lines, re.M)


def test_a_counter_output_whose_angle_moves_less_than_a_count_is_quantized_not_bounded():
    """A 2-arcsec angle counter read at 100 Hz while the angle moves ~0.06 arcsec per
    sample: its quantization error is not white (Q of a white quantizer 0.577 arcsec), so
    the ADEV's bound on an output quantizer (a few tenths of an arcsec) does not hold; the
    fit says the output is quantized instead of "white angle noise, not quantization"."""
    from fogmon.davar.record import lattice_step_dph

    fs, count = 100.0, 2.0
    rate = np.random.default_rng(3).normal(0.0, 0.6 * np.sqrt(fs), 2 ** 18)        # N 0.01 deg/sqrt(h)
    angle = np.floor(np.cumsum(rate / fs) / count) * count                           # arcsec
    counted = np.diff(angle) * fs                                                    # deg/h
    assert lattice_step_dph(counted) == pytest.approx(count * fs)
    assert np.isnan(lattice_step_dph(rate))
    fit = whole_record_fit(counted, None, fs)[1]
    assert fit.Q_arcsec.identifiable and not fit.q_band_limited
    assert fit.quantized_count_arcsec == pytest.approx(count)
    lines = "\n".join(coefficient_lines(fit) + contradiction_lines(fit))
    assert "not quantization" not in lines and "an output quantizer is <" not in lines
    assert "the output is quantized: its samples lie on a lattice of 2 arcsec of angle per sample" in lines


def test_a_hump_fitted_as_a_floor_is_not_printed_identified():
    # white noise and a strong Gauss-Markov hump (tau_c 5 s, peak 37 deg/h at 9.5 s): the
    # robust fit takes the hump's top for B and K and flags the taus beyond it, where the
    # ADEV falls below that floor; the check refuses both and bounds them by the ADEV
    m = SensorModel(100.0, noise=Noise(N_dpsh=0.5), effects=[Effect("markov", {"sigma_dph": 60.0, "tau_c_s": 5.0})])
    rec = simulate(m, duration_s=5000.0, seed=5)
    adev, fit = whole_record_fit(rec.rate_dph, None, 100.0)
    assert {c.name for c in fit.contradicted} == {"B_dph", "K_dphsh"}
    for c in fit.contradicted:
        assert not getattr(fit, c.name).identifiable and float(getattr(fit, c.name).upper) <= c.limit
        assert c.term_adev_dph > c.bound_dph > c.adev_dph
    assert fit.N_dpsh.identifiable
    lines = contradiction_lines(fit)
    assert "B_dph: the fit's 33.06 deg/h is not identified: its flicker floor" in "\n".join(lines)
    assert all(re.search(r"the ADEV bounds it: < \S+ \S+ \(95 % upper limit\)$", ln) for ln in lines), lines


def test_exports_name_a_band_limited_q_as_white_angle_noise():
    from fogmon.export import kalibr_yaml, matlab_snippet

    filtered, quantized = _fit([Effect("bandwidth", {"cutoff_hz": 5.0, "order": 2})]), _fit([])
    for export in (kalibr_yaml, matlab_snippet):
        assert "white angle noise Q (band-limited output, not quantization)" in export(filtered, "rec.csv", 100.0)
        text = export(quantized, "rec.csv", 100.0)
        assert "quantization Q" in text and "white angle noise" not in text


def test_a_filtered_record_gets_the_edf_of_its_noise_not_of_a_ramp():
    # the ADEV rising from the shortest tau (a 1 Hz 4-pole low-pass) was fitted as a ramp R,
    # whose deterministic share put the EDF at 81.92 s near 11,000; the flicker floor's is
    # ~40 (60 records' spread: 45), and below the peak the EDF is no more than at the peak
    m = SensorModel(100.0, noise=Noise(N_dpsh=0.01, B_dph=5.0), effects=[Effect("bandwidth", {"cutoff_hz": 1.0,
                                                                                              "order": 4})])
    adev, _ = whole_record_fit(simulate(m, duration_s=3000.0, seed=1).rate_dph, None, 100.0)
    at = int(np.argmin(np.abs(adev.tau_s - 81.92)))
    assert 25 < adev.edf[at] < 70
    peak = first_peak(adev.adev_dph)
    assert 4 <= peak <= 8                                   # 0.16-2.56 s: the filter's top
    assert np.all(adev.edf[:peak] <= adev.edf[peak] + 1e-9)


def test_every_dadev_window_is_checked_against_its_own_adev(monkeypatch):
    # the 2-D diagram's per-window fits obey the same rule as the whole-record fit: the same
    # Gauss-Markov hump in 5000 s windows; a window whose floor its ADEV refutes prints it
    # as not identifiable, bounded by that window's ADEV; pure noise windows keep theirs
    from fogmon.davar import fit as fit_module
    from fogmon.davar.batch import dadev
    from fogmon.davar.fit import fit_noise, windows_checked_against_adev

    m = SensorModel(10.0, noise=Noise(N_dpsh=0.5), effects=[Effect("markov", {"sigma_dph": 60.0, "tau_c_s": 5.0})])
    rec = simulate(m, duration_s=10000.0, seed=5)
    res = dadev(rec.rate_dph, 10.0, 5000.0, 2500.0)
    fit = fit_noise(res)
    b = fit.B_dph
    assert not np.any(b.identifiable)
    assert np.all(np.asarray(b.value) == 0.0) and np.all(np.asarray(b.hi) == np.asarray(b.upper))
    for i in range(len(res)):
        assert float(b.upper[i]) <= 37.0   # under the hump's top, the ADEV's bound
    clean = dadev(simulate(SensorModel(10.0, noise=Noise(N_dpsh=0.5, B_dph=3.0)), duration_s=10000.0,
                           seed=5).rate_dph, 10.0, 5000.0, 2500.0)
    monkeypatch.setattr(fit_module, "windows_checked_against_adev", lambda f, r: f)
    unchecked = fit_noise(clean)
    assert windows_checked_against_adev(unchecked, clean) is unchecked   # nothing refuted: the same fit
    assert np.any(unchecked.B_dph.identifiable)
