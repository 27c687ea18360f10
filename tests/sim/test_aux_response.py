"""The ``aux_response`` kind in the model file and the simulator (issue 29): the feature
grammar, one-line errors naming file and term, channel units, and the simulated law
(derivatives, cross-axis terms from the other axes' rates, streaming = batch)."""
from __future__ import annotations

import numpy as np
import pytest

from fogmon.cli import main
from fogmon.errors import FogmonError
from fogmon.modelcheck.band import band_effects
from fogmon.sim import effects as fx
from fogmon.sim.features import coef_unit, feature_unit, parse_feature, term_text
from fogmon.sim.model import Effect, Noise, SensorModel, load_model, save_model, validate_effect, validate_model
from fogmon.sim.simulate import iter_simulate, simulate
from fogmon.units import channel_unit


@pytest.mark.parametrize("text, shape, names, canonical", [
    ("vib_g", "linear", ("vib_g",), "vib_g"),
    (" vib_g ^ 2", "square", ("vib_g",), "vib_g^2"),
    ("abs(mag_ut)", "abs", ("mag_ut",), "abs(mag_ut)"),
    ("d(temp_coil_c)/dt", "rate", ("temp_coil_c",), "d(temp_coil_c)/dt"),
    ("vib_g*mag_ut", "product", ("vib_g", "mag_ut"), "vib_g*mag_ut"),
    ("rate_x_dph", "linear", ("rate_x_dph",), "rate_x_dph"),
])
def test_feature_grammar(text, shape, names, canonical):
    f = parse_feature(text)
    assert (f.shape, f.names, f.text) == (shape, names, canonical)


@pytest.mark.parametrize("bad", ["vib_g^3", "sqrt(vib_g)", "d(vib_g)/ds", "a*b*c", "2x", "", "vib-g"])
def test_bad_features_are_one_line_errors_naming_the_term(bad):
    with pytest.raises(FogmonError, match=r"^m.toml: \[\[effect\]\] #1 \(aux_response\): terms\[0\]: feature"):
        validate_effect("aux_response", {"terms": [{"feature": bad, "coef": 1.0}]}, "m.toml: [[effect]] #1")


@pytest.mark.parametrize("terms, message", [
    ([], "non-empty list"),
    ([{"feature": "vib_g"}], "terms\\[0\\]: missing key 'coef'"),
    ([{"feature": "vib_g", "coef": 1.0, "coeff_lo": 0.5}], "unknown key 'coeff_lo'.*did you mean 'coef_lo'"),
    ([{"feature": "vib_g", "coef": 1.0, "coef_lo": 2.0}], "term 'vib_g': coef_lo <= coef <= coef_hi"),
    ([{"feature": "vib_g", "coef": "big"}], "term 'vib_g': coef: expected a finite number"),
    ([{"feature": "vib_g", "coef": 1.0}, {"feature": "vib_g ", "coef": 2.0}], "term 'vib_g': the feature appears"),
])
def test_bad_terms_are_one_line_errors(terms, message):
    with pytest.raises(FogmonError, match=message) as e:
        validate_effect("aux_response", {"terms": terms}, "m.toml: [[effect]] #1")
    assert "\n" not in str(e.value) and str(e.value).startswith("m.toml: [[effect]] #1 (aux_response)")


def test_a_bad_term_in_a_model_file_is_exit_2_naming_file_and_term(tmp_path, capsys):
    p = tmp_path / "m.toml"
    p.write_text('[sensor]\nsample_rate_hz = 10.0\n[noise]\nQ_arcsec = 0.0\nN_dpsh = 0.01\nB_dph = 0.0\n'
                 'K_dphsh = 0.0\nR_dphh = 0.0\n[[effect]]\nkind = "aux_response"\n'
                 'terms = [{feature = "vib_g^2", coef = 0.1}, {feature = "vib_g^4", coef = 0.2}]\n')
    assert main(["sim", "--model", str(p), "--out", str(tmp_path / "o.csv"), "--duration-s", "10"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "m.toml" in err and "terms[1]" in err and "vib_g^4" in err


def test_channel_units_from_names_and_header():
    assert channel_unit("vib_g") == ("acceleration", "g")
    assert channel_unit("mag_ut") == ("magnetic field", "uT")
    assert channel_unit("temp_coil_c") == ("temperature", "degC")
    assert channel_unit("supply_v") == ("voltage", "V")
    assert channel_unit("pumps") == ("", "")
    assert channel_unit("field", {"unit_field": "uT"}) == ("magnetic field", "uT")
    assert feature_unit(parse_feature("d(temp_coil_c)/dt")) == "degC/s"
    assert feature_unit(parse_feature("vib_g*mag_ut")) == "g*uT"
    assert coef_unit(parse_feature("vib_g^2")) == "deg/h per g^2"
    assert coef_unit(parse_feature("acc_mps2^2")) == "deg/h per (m/s^2)^2"
    assert coef_unit(parse_feature("pumps")) == "deg/h per unit of pumps"
    assert term_text({"feature": "rate_x_dph", "coef": 2e-4, "coef_lo": 1.9e-4, "coef_hi": 2.1e-4,
                      "unit": "deg/h per deg/h", "physics": "cross-coupling / misalignment"}) == (
        "cross-coupling / misalignment: bias follows rate_x_dph, 0.0002 deg/h per deg/h [0.00019, 0.00021] "
        "(0.2 mrad)")


def _law(terms, **kw):
    return validate_effect("aux_response", {"terms": [{"feature": f, "coef": c} for f, c in terms], **kw})


def test_round_trip_keeps_every_term_field(tmp_path):
    e = validate_effect("aux_response", {"terms": [
        {"feature": "vib_g^2", "coef": 0.07, "coef_lo": 0.06, "coef_hi": 0.08, "physics": "vibration rectification",
         "colinear": ["vib_g"]}], "physics": "vibration rectification", "offset_dph": -0.3})
    m = validate_model(SensorModel(10.0, 0.0, Noise(N_dpsh=0.01), [e]))
    save_model(m, tmp_path / "m.toml")
    assert load_model(tmp_path / "m.toml") == m
    assert m.effects[0].params["terms"][0]["unit"] == "deg/h per g^2"


def test_the_simulated_law_is_offset_plus_coefficients_times_features():
    t = np.arange(6000) / 10.0
    aux = {"vib_g": 1.0 + 0.5 * np.sin(t / 7.0), "temp_coil_c": 20.0 + 0.02 * t}
    e = _law([("vib_g^2", 0.3), ("d(temp_coil_c)/dt", 50.0)], offset_dph=-0.2)
    want = -0.2 + 0.3 * aux["vib_g"] ** 2 + 50.0 * fx.temperature_derivatives(t, aux["temp_coil_c"])[1]
    assert np.allclose(fx.mean_rate_dph(e, t, aux, 10.0), want)
    quiet = SensorModel(10.0, 0.0, Noise(), [e])
    rec = simulate(quiet, aux=aux, seed=1)
    assert np.allclose(rec.rate_dph, want)
    streamed = np.concatenate([b.rate_dph for b in iter_simulate(quiet, aux=aux, seed=1, chunk_samples=333)])
    assert np.allclose(streamed, want, atol=1e-9)       # the derivative's look-back across chunks


def test_cross_axis_terms_follow_the_other_axis_measured_rate_and_leave_it_alone():
    nz = Noise(N_dpsh=0.01)
    t = np.arange(8000) / 100.0
    aux = {"rot_dps_x": 10.0 * np.sin(2 * np.pi * t / 20.0)}
    law = Effect("aux_response", {"terms": [{"feature": "rate_x_dph", "coef": 2e-4}]}, ("z",))
    m = validate_model(SensorModel(100.0, 0.0, nz, [law], axis_noise={a: nz for a in "xyz"}))
    m0 = validate_model(SensorModel(100.0, 0.0, nz, [], axis_noise={a: nz for a in "xyz"}))
    r, r0 = simulate(m, aux=aux, seed=4), simulate(m0, aux=aux, seed=4)
    assert np.array_equal(r.rate_dph[:, :2], r0.rate_dph[:, :2])
    assert np.allclose(r.rate_dph[:, 2] - r0.rate_dph[:, 2], 2e-4 * r.rate_dph[:, 0])
    streamed = np.concatenate([b.rate_dph for b in iter_simulate(m, aux=aux, seed=4, chunk_samples=1000)])
    assert np.allclose(streamed, r.rate_dph, rtol=0, atol=1e-8)


def test_missing_channels_and_an_axis_own_rate_are_one_line_errors():
    t = np.arange(100) / 10.0
    with pytest.raises(FogmonError, match="needs the aux channel 'mag_ut'"):
        simulate(SensorModel(10.0, 0.0, Noise(N_dpsh=0.01), [_law([("mag_ut", 1.0)])]), aux={"vib_g": t}, seed=1)
    nz = Noise(N_dpsh=0.01)
    m = SensorModel(10.0, 0.0, nz, [Effect("aux_response", {"terms": [{"feature": "rate_x_dph", "coef": 1e-3}]})],
                    axis_noise={a: nz for a in "xz"})
    with pytest.raises(FogmonError, match="axis x reads rate_x_dph, the axis's own rate"):
        simulate(m, duration_s=10.0, seed=1)


def test_the_live_model_check_leaves_a_law_out_of_its_band():
    m = validate_model(SensorModel(10.0, 0.0, Noise(N_dpsh=0.01), [_law([("vib_g^2", 0.1)])]))
    kept, left = band_effects(m)
    assert kept == [] and left == ["aux_response"]
