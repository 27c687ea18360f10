"""Outputs of `fogmon explain` for a recording with several axes (docs/explain.md,
"Several axes"): the report ``{"recording", "model", "axes": {axis: <one-axis
report>}, "common": [...], ...}``, a console summary per axis, the fitted multi-axis
model, the corrected multi-axis replay log and one .rrd with every axis under
``axis/<name>/``. Per-axis files next to the report: ``REPORT.<axis>.png`` and
``REPORT.<axis>.outliers.csv`` (``axis_file``)."""
from __future__ import annotations

import os
from dataclasses import replace

import numpy as np

from fogmon.explain import report
from fogmon.explain.axes import AxesResult
from fogmon.formats.replay_log import write_replay_log
from fogmon.sim.model import save_model


def axis_file(report_path: str, axis: str, suffix: str) -> str:
    """A per-axis file next to the report: ``REPORT.<axis><suffix>`` (suffix ".png",
    ".outliers.csv")."""
    return f"{os.path.splitext(report_path)[0]}.{axis}{suffix}"


def build_axes_report(ares: AxesResult, recording_path: str, model_path: str | None,
                      times_files: dict[str, str] | None = None) -> dict:
    """The multi-axis report (docs/formats.md): each explained axis's one-axis report
    under ``axes`` (``times_files``: its outliers file, relative to the report),
    ``common``, the axes' scores combined (``AxesResult.score_before``), the
    model_axis_missing ``warnings`` and a ``verdict``."""
    axes = {a: report.build_report(res, recording_path, model_path, (times_files or {}).get(a, ""))
            for a, res in ares.results.items()}
    rep = {
        "recording": recording_path,
        "model": axes[next(iter(axes))]["model"],
        "axes": axes,
        "common": [c.as_json(ares.results) for c in ares.common],
        "score_before": round(ares.score_before, 3),
        "score_after": round(ares.score_after, 3),
        "warnings": ares.warnings,
        "verdict": axes_verdict(ares, axes),
        "method": {"axes_explained": list(ares.results), "axes_recorded": list(ares.recording.axes),
                   "score": "smooth maximum (power mean, power 8) of the axes' scores"},
    }
    return report.json_safe(rep)


def axes_verdict(ares: AxesResult, axes: dict[str, dict]) -> str:
    """One paragraph over the axes: what each needs, the common causes and how strongly
    the data show them, the axes not explained."""
    parts = [f"Each axis explained on its own against {'its baseline' if ares.baseline else 'its model'} "
             f"(its own verdict in its report); combined score {ares.score_before:.2f} -> {ares.score_after:.2f}."]
    for a, rep in axes.items():
        if rep["effects"]:
            what = "; ".join(report.effect_summary(e["kind"], e["params"], e.get("model_noise"))
                             for e in rep["effects"])
            left = f", {len(rep['mismatches_after'])} region(s) left" if rep["mismatches_after"] else ""
            parts.append(f"Axis {a}: {what} (score {rep['score_before']:.2f} -> {rep['score_after']:.2f}{left}).")
        elif rep["mismatches"]:
            parts.append(f"Axis {a}: {len(rep['mismatches'])} mismatch region(s) no catalogued effect explains "
                         f"(score {rep['score_before']:.2f}).")
        else:
            parts.append(f"Axis {a}: explained by {'its baseline' if ares.baseline else 'the model'} "
                         f"(score {rep['score_before']:.2f}).")
    for c in ares.common:
        how = ("the axes' data cohere beyond chance on every pair" if c.significant else
               "but the axes' data do not cohere beyond chance on every pair (see its evidence)")
        what = f"{c.kind} ({c.feature})" if c.feature else c.kind
        parts.append(f"Common cause: {what} driven by {c.channel} on axes {', '.join(c.axes)}, {how}.")
    if not ares.common:
        parts.append("No effect is shared across axes through one aux channel.")
    for w in ares.warnings:
        parts.append(f"Not explained: {w['text']}.")
    return " ".join(parts)


def axes_console_summary(rep: dict) -> str:
    """A few lines per axis (``report.console_summary`` of its report), then the common
    causes, the warnings and the verdict."""
    lines = [f"fogmon explain: {os.path.basename(rep['recording'])} vs {rep['model']} "
             f"(axes {', '.join(rep['axes'])})",
             f"  score before {rep['score_before']:.2f} -> after {rep['score_after']:.2f} "
             f"(smooth maximum over the axes; about 1 = chance)"]
    for a, one in rep["axes"].items():
        body = report.console_summary(one).splitlines()[1:]
        lines.append(f"  axis {a}:")
        lines += ["  " + s for s in body if not s.startswith("  verdict: ")]
    for c in rep["common"]:
        lines.append(f"  common: {c['kind']} via {c['aux_channel']} on axes {', '.join(c['axes'])} "
                     f"({'coherent' if c['significant'] else 'not significantly coherent'} across axes)")
    if not rep["common"]:
        lines.append("  common: none")
    for w in rep["warnings"]:
        lines.append(f"  warning {w['kind']}: {w['text']}")
    lines.append("  verdict: " + rep["verdict"])
    return "\n".join(lines)


def write_axes_outputs(ares: AxesResult, out_model: str | None, out_corrected: str | None,
                       outliers_files: dict[str, str] | None = None) -> None:
    """--out-model: the fitted multi-axis model (``fitted_model``; an axis's ``outliers``
    effect names its file of ``outliers_files`` relative to the model). --out-corrected: the
    recording with each axis's fitted deterministic effects removed (as
    ``report.write_outputs`` does for one axis) as a multi-axis replay log; a sample an
    axis left out for platform motion is left out of every axis (one time column), an
    axis not explained is written as recorded, and ``corrected_by_<axis>`` says what
    was removed from each."""
    if out_model:
        fitted = ares.fitted
        for a, path in (outliers_files or {}).items():
            rel = os.path.relpath(path, os.path.dirname(os.path.abspath(out_model)))
            fitted = replace(fitted, effects=[replace(e, params={**e.params, "times_file": rel})
                                              if e.kind == "outliers" and e.axes == (a,) else e
                                              for e in fitted.effects])
        save_model(fitted, out_model)
    if out_corrected:
        rec = ares.recording
        keep = np.ones(len(rec), bool)
        rate = rec.rate_dph.copy()
        meta = {**rec.meta, "sample_rate_hz": f"{rec.sample_rate_hz:g}"}
        meta.pop("axis", None)
        for a, res in ares.results.items():
            rows = np.searchsorted(rec.t_s, res.recording.t_s)
            kept = np.zeros(len(rec), bool)
            kept[rows] = True
            keep &= kept
            rate[rows, rec.axes.index(a)] = report.corrected_rate_dph(res)
            meta.update(report.corrected_meta(res, f"_{a}"))
        for a in rec.axes:
            if a not in ares.results:
                meta[f"corrected_by_{a}"] = "nothing (axis not explained: the model has no table for it)"
        write_replay_log(out_corrected, rec.t_s[keep], rate[keep], {k: v[keep] for k, v in rec.aux.items()}, meta,
                         axes=rec.axes)


def write_axes_rrd(ares: AxesResult, path: str) -> None:
    """One Rerun recording with each axis's explain evidence (``report.log_rrd``) under
    ``axis/<name>/``, a tab per axis (``report.rrd_layout``), and the combined verdict
    with the common causes at ``verdict``."""
    import rerun as rr
    import rerun.blueprint as rrb

    adev = {a: report.rrd_adev_logs(res) for a, res in ares.results.items()}
    tabs = [report.rrd_layout(adev[a][2], adev[a][3], f"axis/{a}/", f"axis {a}") for a in ares.results]
    text = build_axes_report(ares, ares.recording.name, None)
    summary = text["verdict"] + "".join(f"\n\n{c['evidence']}" for c in text["common"])
    bp = rrb.Blueprint(rrb.Tabs(*tabs, rrb.TextDocumentView(origin="/verdict", name="All axes: verdict and common "
                                                             "causes")),
                       rrb.TimePanel(timeline="time", state="collapsed"), collapse_panels=True)
    rec = rr.RecordingStream("fogmon_explain")
    rec.save(path, default_blueprint=bp)
    for a, res in ares.results.items():
        report.log_rrd(rec, res, adev[a], f"axis/{a}/")
    rec.log("verdict", rr.TextDocument(summary), static=True)
    rec.flush()
