"""`fogmon explain` end to end on small simulated recordings: the report of docs/formats.md, a
concealed effect found and fitted, a null recording left alone, one-line errors, and
the independent check that the fitted model re-simulated --like the recording stays
inside the bootstrap bands where the original model does not."""
import json
import math

import numpy as np
import pytest
from helpers.explain import assert_invariants

from fogmon.cli import main
from fogmon.explain import mismatch
from fogmon.explain.explainer import explain
from fogmon.explain.options import Options
from fogmon.formats.replay_log import read_replay_log, write_replay_log
from fogmon.sim.model import Effect, Noise, SensorModel, load_model, save_model
from fogmon.sim.simulate import simulate

FS = 10.0
NOISE = Noise(N_dpsh=0.01, B_dph=0.01)
SIGMA = 60 * 0.01 * math.sqrt(FS)            # per-sample white std, deg/h
PERIODIC = Effect("periodic", {"period_s": 300.0, "amplitude_dph": 0.25 * SIGMA, "phase_rad": 0.7})


def _write(tmp_path, effects, seed=5, duration_s=3600.0, aux=None):
    truth = SensorModel(FS, 2.0, NOISE, effects)
    rec = simulate(truth, duration_s=duration_s, seed=seed, aux=aux)
    path = tmp_path / "rec.csv"
    write_replay_log(path, rec.t_s, rec.rate_dph, rec.aux, {"sample_rate_hz": "10"})
    mpath = tmp_path / "model.toml"
    save_model(SensorModel(FS, 2.0, NOISE, []), mpath)
    return path, mpath


def test_concealed_periodic_is_found_fitted_and_removed(tmp_path, capsys):
    rec, model = _write(tmp_path, [PERIODIC])
    rep_p, fit_p, cor_p = tmp_path / "rep.json", tmp_path / "fit.toml", tmp_path / "cor.csv"
    rc = main(["explain", str(rec), "--model", str(model), "--report", str(rep_p), "--bootstrap", "30",
               "--out-model", str(fit_p), "--out-corrected", str(cor_p), "--rrd", str(tmp_path / "e.rrd")])
    assert rc == 0
    rep = json.loads(rep_p.read_text())
    for k in ("recording", "model", "mismatches", "effects", "score_before", "score_after", "verdict"):
        assert k in rep
    assert rep["mismatches"] and {"t_start_s", "t_end_s", "tau_min_s", "tau_max_s", "ratio", "p_value"} <= set(
        rep["mismatches"][0])
    assert [e["kind"] for e in rep["effects"]] == ["periodic"]
    assert_invariants(rep, 0.0, 3600.0)
    p = rep["effects"][0]["params"]
    assert p["period_s"] == pytest.approx(300.0, rel=0.01)
    assert p["amplitude_dph"] == pytest.approx(0.25 * SIGMA, rel=0.15)
    assert rep["score_before"] > 3.0 and rep["score_after"] <= 1.5 and rep["mismatches_after"] == []
    assert (tmp_path / "rep.png").stat().st_size > 10_000 and (tmp_path / "e.rrd").stat().st_size > 1000
    _check_rrd(str(tmp_path / "e.rrd"), rep)
    fitted = load_model(fit_p)
    assert [e.kind for e in fitted.effects] == ["periodic"]
    cor = read_replay_log(cor_p)
    raw = read_replay_log(rec)
    line = np.sin(2 * np.pi * raw.t_s / 300.0 + 0.7)
    assert abs(np.dot(raw.rate_dph - raw.rate_dph.mean(), line)) / np.dot(line, line) > 0.2 * SIGMA
    assert abs(np.dot(cor.rate_dph - cor.rate_dph.mean(), line)) / np.dot(line, line) < 0.03 * SIGMA
    cap = capsys.readouterr()
    assert "score before" in cap.out and "periodic" in cap.out
    stages = cap.err.splitlines()     # progress on stderr: stages as lines (the bar only on a terminal)
    assert stages[:4] == [f"fogmon explain: reading {rec}",
                          "fogmon explain: looking for platform motion",
                          "fogmon explain: bootstrap null: 30 simulations of the model like the recording",
                          "fogmon explain: mismatch map and candidate effects"]
    assert stages[4].startswith("fogmon explain: effect 1: periodic (score ")
    assert stages[-1] == f"fogmon explain: writing {rep_p}"


def _check_rrd(path, rep):
    """The explain .rrd carries its layout (a blueprint with the five views) and static
    evidence that shows whatever the time cursor: labelled log-log ADEV, z-map images."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    (bp,) = reader.blueprints()
    views = {str(c.entity_path) for c in reader.stream(store=bp) if str(c.entity_path).count("/") == 2
             and str(c.entity_path).startswith("/view/")}
    assert len(views) == 5
    static = {str(c.entity_path) for c in reader.stream().filter(is_static=True)}
    assert {"/adev/log10/before/recording_residual", "/adev/log10/after/recording_residual", "/adev/log10/legend",
            "/adev/log10/grid_labels", "/zmap_before/map/image", "/zmap_after/map/image", "/zmap_before/labels",
            "/verdict"} <= static
    if any(not m["whole_record"] for m in rep["mismatches"]):
        assert "/zmap_before/map/regions" in static            # flagged regions outlined on the map
    if any(m["whole_record"] for m in rep["mismatches"]):     # no time: boxed on the ADEV plot, noted on the map
        assert {"/adev/log10/whole_record_regions/boxes", "/zmap_before/note"} <= static
    assert {"/adev/log10/before/model_band/bars", "/adev/log10/after/model_band/bars"} <= static
    n_windows, n_taus = rep["method"]["n_windows"], len(rep["method"]["taus_s"])
    for ch in reader.stream().filter(content="/zmap_before/map/image"):
        fmt = ch.to_record_batch().column("Image:format").to_pylist()[0][0]
        assert (fmt["width"], fmt["height"]) == (n_windows, n_taus)


def test_null_recording_gives_no_effect_and_no_region(tmp_path, capsys):
    rec, model = _write(tmp_path, [], seed=11)
    rep_p = tmp_path / "rep.json"
    assert main(["explain", str(rec), "--model", str(model), "--report", str(rep_p), "--bootstrap", "30",
                 "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")    # --quiet: no progress, no summary
    rep = json.loads(rep_p.read_text())
    assert rep["effects"] == [] and rep["mismatches"] == []
    assert [w["kind"] for w in rep["warnings"]] == ["record_too_short"]  # B = 0.01 is 9 % of the avar at 819 s
    assert_invariants(rep, 0.0, 3600.0)
    assert rep["score_before"] <= 1.5 and "explains the recording" in rep["verdict"]


def test_fitted_model_resimulated_like_the_recording_stays_inside_the_bootstrap_bands(tmp_path):
    truth = SensorModel(FS, 2.0, NOISE, [Effect("periodic", {"period_s": 300.0, "amplitude_dph": 0.5 * SIGMA,
                                                             "phase_rad": 0.7})])
    rec = simulate(truth, duration_s=3600.0, seed=21)
    base = SensorModel(FS, 2.0, NOISE, [])
    res = explain(rec, base, Options(n_boot=30, seed=3))
    null, grid = res.before.null, res.grid
    cell_rec, _ = mismatch.log_avar(rec.rate_dph, np.ones(len(rec), bool), grid)
    worst = {}
    for name, model in (("fitted", res.fitted), ("original", base)):
        sim = simulate(model, like=rec, seed=77)
        cell_sim, _ = mismatch.log_avar(sim.rate_dph, np.ones(len(sim), bool), grid)
        worst[name] = float(np.nanmax(np.abs(mismatch.compare_maps(cell_sim, cell_rec, null))))
    assert worst["fitted"] < null.threshold < worst["original"]


def _err(capsys, argv):
    rc = main([*argv, "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and "Traceback" not in err
    return err


def test_bad_inputs_give_one_line_errors(tmp_path, capsys):
    rec, model = _write(tmp_path, [], duration_s=1800.0)
    rep = str(tmp_path / "r.json")
    m100 = tmp_path / "m100.toml"
    save_model(SensorModel(100.0, 0.0, NOISE, []), m100)
    assert "does not match the model's [sensor] sample_rate_hz = 100 Hz" in _err(
        capsys, ["explain", str(rec), "--model", str(m100), "--report", rep])
    mt = tmp_path / "thermal.toml"
    save_model(SensorModel(FS, 0.0, NOISE, [Effect("thermal_drift", {"k0_poly_dph": [], "k1_pos": 1.0, "k1_neg": 1.0,
                                                                      "k2_pos": 0.0, "k2_neg": 0.0})]), mt)
    assert f"--model {mt}: [[effect]] #1 (thermal_drift) needs the aux channel 'temp_c'" in _err(
        capsys, ["explain", str(rec), "--model", str(mt), "--report", rep])
    assert "too short for the 1000 s map window" in _err(
        capsys, ["explain", str(rec), "--model", str(model), "--report", rep, "--window-s", "1000"])
    assert "no such file" in _err(capsys, ["explain", str(tmp_path / "nope.csv"), "--report", rep])
    stuck = tmp_path / "stuck.csv"                  # a stuck output: no noise, against a model or a baseline
    write_replay_log(stuck, np.arange(20000) / FS, np.full(20000, 5.0), {}, {"sample_rate_hz": FS})
    for more in ([], ["--model", str(model)]):
        assert "the rate is 5 deg/h at every one of its 20000 samples: a stuck or saturated output" in _err(
            capsys, ["explain", str(stuck), "--report", rep, *more])
    assert not (tmp_path / "r.json").exists()


@pytest.mark.parametrize("argv, message", [
    (["--bootstrap", "100000000"], "argument --bootstrap: must be an integer in 8..10000, got '100000000'"),
    (["--bootstrap", "7"], "argument --bootstrap: must be an integer in 8..10000, got '7'"),
    (["--seed", "-1"], "argument --seed: must be an integer >= 0, got '-1'"),
    (["--max-effects", "-1"], "argument --max-effects: must be an integer >= 0, got '-1'"),
    (["--window-s", "inf"], "argument --window-s: must be a finite number > 0, got 'inf'"),
    (["--alpha", "nan"], "argument --alpha: must be a finite number > 0 and <= 0.5, got 'nan'"),
])
def test_bad_option_values_are_usage_errors(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit) as e:
        main(["explain", str(tmp_path / "rec.csv"), "--report", str(tmp_path / "r.json"), *argv])
    assert e.value.code == 2
    assert capsys.readouterr().err == f"fogmon explain: error: {message} (see fogmon explain --help)\n"


@pytest.mark.parametrize("opts, message", [
    (["--report", "{tmp}/no/r.json"], "--report {tmp}/no/r.json: folder {tmp}/no does not exist"),
    (["--report", "{tmp}"], "--report {tmp}: is a folder, give a file name"),
    (["--report", "/proc/r.json"], "--report /proc/r.json: cannot write: No such file or directory"),
    (["--report", "{tmp}/r.json", "--out-model", "{tmp}"], "--out-model {tmp}: is a folder, give a file name"),
    (["--report", "{tmp}/r.json", "--rrd", "{tmp}/no/e.rrd"], "--rrd {tmp}/no/e.rrd: folder {tmp}/no does not "
                                                               "exist"),
    (["--report", "{tmp}/r.json", "--out-corrected", "{tmp}/rec.csv"], "--out-corrected {tmp}/rec.csv: is the "
                                                                       "input {tmp}/rec.csv; write to another file"),
    (["--report", "{tmp}/r.json", "--out-model", "{tmp}/r.json"], "--out-model {tmp}/r.json: also given as --report"),
])
def test_unwritable_outputs_fail_before_any_work_and_create_nothing(tmp_path, capsys, opts, message):
    rec, _ = _write(tmp_path, [], duration_s=600.0)
    before = sorted(tmp_path.iterdir())
    opts = [o.format(tmp=tmp_path) for o in opts]
    assert main(["explain", str(rec), *opts]) == 2
    assert capsys.readouterr().err == f"fogmon explain: error: {message.format(tmp=tmp_path)}\n"  # no stage ran
    assert sorted(tmp_path.iterdir()) == before


def test_progress_bar_on_a_terminal():
    import io

    from fogmon.cli.explain import StageProgress

    s = io.StringIO()
    p = StageProgress(s, bar=True)
    p("bootstrap null: 3 simulations")
    for i in range(1, 4):
        p("bootstrap", i, 3)
    p("writing r.json")
    out = s.getvalue()
    assert out.startswith("fogmon explain: bootstrap null: 3 simulations\n")
    assert out.endswith("fogmon explain: writing r.json\n")
    bar = out.split("\n")[1].split("\r")[-1]         # the bar's last state (tqdm), closed before the next stage
    assert bar.startswith("  bootstrap: 100%") and "3/3" in bar
    assert StageProgress(io.StringIO()).bar is False   # not a terminal: stage lines only, no bar
