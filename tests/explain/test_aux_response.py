"""`fogmon explain` names laws outside the catalogue (``aux_response``, issue 29): the
stepwise candidate on the calibrated Whittle GLS (terms, intervals, physics, colinear
features, nothing below its bar on a null), the look-alike rule against the catalogue,
the axes' rate columns as features, and the end-to-end report, fitted model,
re-simulation and correction."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fogmon.cli import main
from fogmon.explain import lookalike, mismatch
from fogmon.explain.analysis import whittle_context
from fogmon.explain.axes import _causes, with_other_rates
from fogmon.explain.candidates.aux_response import CATALOGUE_FEATURES, _library, aux_response
from fogmon.explain.candidates.mean import bias_step, scale_factor
from fogmon.explain.explainer import explain
from fogmon.explain.options import Options
from fogmon.explain.physics import physics_of
from fogmon.explain.report import build_report, write_outputs
from fogmon.formats.recording import recording_from_arrays
from fogmon.formats.replay_log import read_replay_log, write_replay_log
from fogmon.modelcheck.band import band_model
from fogmon.sim.features import parse_feature
from fogmon.sim.model import Effect, Noise, SensorModel, load_model, save_model
from fogmon.sim.simulate import simulate

FS = 10.0
NOISE = Noise(N_dpsh=0.01)
SIGMA = 60 * 0.01 * math.sqrt(FS)


def _ctx(y, aux, meta=None):
    n = len(y)
    t = np.arange(n) / FS
    ctx = whittle_context(SensorModel(FS, 0.0, NOISE, []), aux, t, np.ones(n, bool), y)
    ctx.meta = meta or {}
    return ctx


def _channels(n, seed):
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    return {"vib_g": 1.0 + 0.6 * np.abs(np.sin(k / 900.0) + 0.3 * rng.standard_normal(n).cumsum() / 300.0),
            "mag_ut": 50.0 * np.sign(np.sin(k / 1300.0)) + rng.standard_normal(n),
            "temp_coil_c": 25.0 + 3.0 * np.sin(k / 5000.0)}


def test_the_law_is_found_among_decoy_channels_with_its_interval_and_physics():
    n = 36000
    rng = np.random.default_rng(1)
    aux = _channels(n, 2)
    y = SIGMA * rng.standard_normal(n) + 0.3 * aux["vib_g"] ** 2
    c = aux_response(_ctx(y, aux))
    terms = c.params["terms"]
    assert [t["feature"] for t in terms] == ["vib_g^2"]
    t = terms[0]
    assert t["coef_lo"] < 0.3 < t["coef_hi"] and t["unit"] == "deg/h per g^2"
    assert t["physics"] == c.params["physics"] == "vibration rectification"
    assert c.k == 1 and c.search_bar > math.log(n) and c.bic_gain(math.log(n)) > 0
    assert c.design.shape == (n, 1) and abs(np.mean(c.rate)) < 1e-9   # offset: the law averages 0


def test_colinear_features_are_named_not_split():
    n = 36000
    rng = np.random.default_rng(3)
    a = np.sin(np.arange(n) / 700.0) + 0.2 * rng.standard_normal(n)
    aux = {"a_g": a, "b_g": a + 0.01 * rng.standard_normal(n)}
    c = aux_response(_ctx(SIGMA * rng.standard_normal(n) + 0.5 * a, aux))
    (t,) = c.params["terms"]
    assert {t["feature"], *t["colinear"]} == {"a_g", "b_g"}
    assert "are colinear here" in c.evidence and "the data cannot tell them apart" in c.evidence


def test_on_noise_alone_the_best_feature_stays_below_its_bar():
    n = 36000
    y = SIGMA * np.random.default_rng(5).standard_normal(n)
    ctx = _ctx(y, _channels(n, 6))
    c = aux_response(ctx)
    assert c.k == 1 and c.bic_gain(ctx.penalty) <= 0


def test_catalogue_features_are_left_to_the_catalogue_and_units_come_from_the_header():
    n = 4000
    rng = np.random.default_rng(7)
    aux = {"temp_c": 20 + rng.standard_normal(n).cumsum() / 50, "rot_dps": rng.standard_normal(n),
           "field": rng.standard_normal(n)}
    lib = _library(_ctx(rng.standard_normal(n), aux))
    texts = {f.text for f in lib.features}
    assert not texts & CATALOGUE_FEATURES and "rot_dps^2" in texts and "temp_c*rot_dps" in texts
    assert physics_of(parse_feature("field"), {"unit_field": "uT"}) == "magnetic (Faraday) sensitivity"
    assert physics_of(parse_feature("field")) == ""                      # nothing invented
    assert physics_of(parse_feature("rate_y_dph")) == "cross-coupling / misalignment"


def test_a_real_bias_step_refuses_a_channel_that_only_partly_follows_it():
    n = 36000
    rng = np.random.default_rng(8)
    k = np.arange(n)
    mag = np.where((k > n // 2) & (k < 0.8 * n), 40.0, 0.0)          # on at the step, off again later
    y = SIGMA * rng.standard_normal(n) + np.where(k >= n // 2, 0.3 * SIGMA, 0.0)
    ctx = _ctx(y, {"mag_ut": mag})
    law, step = aux_response(ctx), bias_step(ctx)
    assert law.bic_gain(ctx.penalty) > 0 and step.bic_gain(ctx.penalty) > 0
    why = lookalike.refusal(law, [law, step], ctx)
    assert why is not None and why.startswith("a look-alike of bias_step")


def _switched_rotation():
    """A context whose rotation switches between 0 and 20 deg/s, with a 30 ppm scale factor."""
    n = 36000
    rng = np.random.default_rng(10)
    rot = np.where((np.arange(n) // 3000) % 2 == 1, 20.0, 0.0)
    y = SIGMA * rng.standard_normal(n) + 3600.0 * rot * 30e-6
    return _ctx(y, {"rot_dps": rot})


def test_a_tie_with_a_catalogue_kind_on_its_own_channel_keeps_the_catalogue():
    """A rotation switched between 0 and one rate makes rot_dps^2 the same feature as
    rot_dps: the scale factor (the catalogue's physics on that channel) is kept."""
    ctx = _switched_rotation()
    law, sf = aux_response(ctx), scale_factor(ctx)
    assert law.bic_gain(ctx.penalty) > 0 and sf.bic_gain(ctx.penalty) > 0
    why = lookalike.refusal(law, [law, sf], ctx)
    assert why is not None and why.startswith("a look-alike of scale_factor") and "catalogue's physics" in why


def test_a_look_alike_kept_without_its_design_is_fitted_again_for_the_comparison():
    """The selection keeps only each tier's best candidate whole (bounded memory): the
    catalogue look-alike arrives without its design and is fitted again, so the rule
    still holds (without the refit the law took the scale factor's place: the devset's
    rate-table and thermal-chamber cases named aux_response)."""
    from fogmon.explain.selection import fitted, light
    ctx = _switched_rotation()
    law, sf = aux_response(ctx), light(scale_factor(ctx))
    assert sf.design is None
    why = lookalike.refusal(law, [law, sf], ctx, lambda o: fitted(o.kind, ctx, {}))
    assert why is not None and why.startswith("a look-alike of scale_factor")


def test_a_stepped_channel_is_judged_first_and_explains_the_step():
    n = 36000
    rng = np.random.default_rng(9)
    k = np.arange(n)
    mag = np.where(k >= n // 2, 40.0, 0.0) + np.where((k > 0.2 * n) & (k < 0.3 * n), -40.0, 0.0)
    y = SIGMA * rng.standard_normal(n) + 0.01 * mag
    ctx = _ctx(y, {"mag_ut": mag})
    law, step = aux_response(ctx), bias_step(ctx)
    assert lookalike.first([step, law], ctx.penalty) == [law, step]
    assert lookalike.refusal(law, [law, step], ctx) is None
    after = _ctx(y - law.rate, {"mag_ut": mag})
    told = lookalike.explained(law, [law, step], [aux_response(after), bias_step(after)], ctx.penalty)
    assert "Look-alikes refused, explained by the law: bias_step (BIC gain" in told.evidence


def test_each_axis_sees_the_other_axes_rates_and_a_shared_channel_is_a_common_cause():
    t = np.arange(10) / FS
    rec = recording_from_arrays(t, np.column_stack([t, 2 * t, 3 * t]), {"vib_g": t, "temp_c_z": t},
                                {"sample_rate_hz": "10"}, axes=("x", "y", "z"))
    z = with_other_rates(rec, "z")
    assert set(z.aux) == {"vib_g", "temp_c", "rate_x_dph", "rate_y_dph"}
    assert np.array_equal(z.aux["rate_x_dph"], t) and np.array_equal(z.rate_dph, 3 * t)
    params = {"terms": [{"feature": "vib_g^2"}, {"feature": "rate_x_dph"}, {"feature": "d(temp_c)/dt"}]}
    assert _causes(rec, "z", "aux_response", params) == [("vib_g", "vib_g^2"), ("temp_c_z", "d(temp_c_z)/dt")]


def test_end_to_end_report_fitted_model_resimulation_and_correction(tmp_path):
    """A field stepped between levels drives the bias (Faraday): explain names the law, not
    bias steps; the fitted model re-simulated like the recording stays inside the bootstrap
    bands where the original does not; --out-corrected removes the law; the live check
    takes the fitted model."""
    n = 18000
    t = np.arange(n) / FS
    mag = 40.0 * np.floor(3 * (1 + np.sin(2 * np.pi * t / 900.0)))             # held steps, 0..240 uT
    coef = 0.5 * SIGMA / 80.0
    rec = simulate(SensorModel(FS, 2.0, NOISE, [Effect("aux_response", {"terms": [{"feature": "mag_ut",
                                                                                   "coef": coef}]})]),
                   aux={"mag_ut": mag}, seed=12)
    rec.path = str(tmp_path / "rec.csv")
    base = SensorModel(FS, 2.0, NOISE, [])
    res = explain(rec, base, Options(n_boot=30, seed=3))
    rep = build_report(res, rec.path, "model.toml")
    assert [e["kind"] for e in rep["effects"]] == ["aux_response"]
    (term,) = rep["effects"][0]["params"]["terms"]
    assert term["feature"] == "mag_ut" and term["coef_lo"] < coef < term["coef_hi"]
    assert "magnetic (Faraday) sensitivity: bias follows mag_ut" in rep["verdict"]
    assert rep["score_after"] <= 1.5 and rep["mismatches_after"] == []
    fit_p, cor_p = tmp_path / "fit.toml", tmp_path / "cor.csv"
    write_outputs(res, str(fit_p), str(cor_p))
    fitted = load_model(fit_p)
    band_model(fitted, FS)                                       # the live --model check takes it
    null, grid = res.before.null, res.grid
    cell_rec, _ = mismatch.log_avar(rec.rate_dph, np.ones(n, bool), grid)
    worst = {}
    for name, model in (("fitted", fitted), ("original", base)):
        sim = simulate(model, like=rec, seed=78)
        cell_sim, _ = mismatch.log_avar(sim.rate_dph, np.ones(n, bool), grid)
        worst[name] = float(np.nanmax(np.abs(mismatch.compare_maps(cell_sim, cell_rec, null))))
    assert worst["fitted"] < null.threshold < worst["original"]
    cor = read_replay_log(cor_p)
    x = mag - mag.mean()
    left = np.dot(cor.rate_dph - cor.rate_dph.mean(), x) / np.dot(x, x)
    assert abs(left) < 0.1 * coef and "aux_response" in cor.meta["corrected_by"]


@pytest.mark.parametrize("feature", ["mag_ut", "d(temp_coil_c)/dt"])
def test_a_model_law_needs_its_channels_in_the_recording(tmp_path, capsys, feature):
    t = np.arange(3000) / FS
    path, mpath = tmp_path / "rec.csv", tmp_path / "m.toml"
    write_replay_log(path, t, np.zeros(len(t)), {"vib_g": t}, {"sample_rate_hz": "10"})
    save_model(SensorModel(FS, 0.0, NOISE, [Effect("aux_response", {"terms": [{"feature": feature, "coef": 1.0}]})]),
               mpath)
    assert main(["explain", str(path), "--model", str(mpath), "--report", str(tmp_path / "r.json"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "aux_response" in err and parse_feature(feature).names[0] in err
