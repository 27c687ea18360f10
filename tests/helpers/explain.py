"""`fogmon explain` in tests: the report invariants of docs/formats.md (issue 11) every
test checks, and one explain run of a simulated recording against a model."""
from __future__ import annotations

import json
import os
import re

from fogmon.cli import main
from fogmon.formats.replay_log import read_replay_log, write_replay_log
from fogmon.sim.model import SensorModel, load_model, save_model
from fogmon.sim.simulate import simulate

WARNING_KEYS = {"kind", "t_start_s", "t_end_s", "text"}


def assert_invariants(rep: dict, t0: float, t1: float, report_dir=None) -> None:
    """The report invariants of docs/formats.md / issue 11; no list cut: a glitches
    effect lists every spike its evidence counts, an outliers effect names the file (in
    ``report_dir``, when the report was written there) holding all it counts."""
    for e in rep["effects"]:
        assert e["score_after"] < e["score_before"], e
        if e["kind"] == "glitches":
            counted = re.search(r"(\d+) sample\(s\) beyond", e["evidence"])
            assert counted and int(counted.group(1)) == len(e["params"]["times_s"]), e["evidence"]
        if e["kind"] == "outliers" and report_dir is not None:
            with open(os.path.join(report_dir, e["params"]["times_file"])) as fh:
                rows = [line for line in fh if line.strip() and not line.startswith("#")]
            left = [w for w in rep["warnings"] if w["kind"] == "spikes"]
            listed = e["params"]["count"] + (int(re.search(r"finds (\d+) sample", left[0]["text"]).group(1))
                                             if left else 0)
            assert rows[0].strip() == "time_s,amplitude_dph,abs_z" and len(rows) - 1 == listed > 0
    for r in rep["mismatches"] + rep["mismatches_after"]:
        assert t0 - 1e-6 <= r["t_start_s"] <= r["t_peak_s"] <= r["t_end_s"] <= t1 + 1e-6, r
    assert isinstance(rep["warnings"], list)
    for w in rep["warnings"]:
        assert set(w) == WARNING_KEYS and w["kind"] in ("platform_motion", "record_too_short", "model_axis_missing",
                                                        "nonstationary", "spikes", "lookalike")
        assert t0 - 1e-6 <= w["t_start_s"] <= w["t_end_s"] <= t1 + 1e-6


def explain_run(tmp_path, truth: SensorModel, model: SensorModel, duration_s: float, seed: int):
    """`fogmon explain` of a simulation of ``truth`` (``duration_s`` s, ``seed``) against
    ``model`` in ``tmp_path``: (report, the fitted model, the recording, the corrected
    recording), the report checked by ``assert_invariants``."""
    rec = simulate(truth, duration_s=duration_s, seed=seed)
    path, mpath = tmp_path / "rec.csv", tmp_path / "model.toml"
    write_replay_log(path, rec.t_s, rec.rate_dph, rec.aux, {"sample_rate_hz": f"{truth.sample_rate_hz:g}"})
    save_model(model, mpath)
    rep_p, fit_p, cor_p = tmp_path / "rep.json", tmp_path / "fit.toml", tmp_path / "cor.csv"
    assert main(["explain", str(path), "--model", str(mpath), "--report", str(rep_p), "--bootstrap", "30",
                 "--out-model", str(fit_p), "--out-corrected", str(cor_p), "--quiet"]) == 0
    rep = json.loads(rep_p.read_text())
    assert_invariants(rep, float(rec.t_s[0]), float(rec.t_s[-1]) + 1.0 / truth.sample_rate_hz)
    return rep, load_model(fit_p), read_replay_log(path), read_replay_log(cor_p)
