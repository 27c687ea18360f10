"""`fogmon explain RECORDING.csv [--model MODEL.toml] --report REPORT.json [...]`:
locate where the recording's dynamic Allan deviation leaves what the model can
produce, name and fit the missing physics, show the fit improve (docs/formats.md)."""
from __future__ import annotations

import argparse
import os
import sys
from typing import Any, TextIO

from fogmon.cli.export_options import add_export_argument, export_request
from fogmon.cli.helptext import set_epilog
from fogmon.cli.source_options import add_reader_arguments, source_options
from fogmon.cli.values import number, positive
from fogmon.explain.options import MAX_GROWTH, SETTLE_SE
from fogmon.export import write_export
from fogmon.outputs import check_outputs, written

#: Most bootstrap replicates: each is one simulation of the whole recording, and beyond
#: this the Gumbel-fitted family-wise threshold no longer sharpens.
MAX_BOOTSTRAP = 10_000


EXAMPLES = """
fogmon explain replay_logs/sim_in_orbit_1hz.csv --report report.json --out-model fitted.toml
fogmon explain replay_logs/sim_mwd_run_1hz.csv --model replay_logs/sim_mwd_run.toml --report mwd.json --rrd mwd.rrd
fogmon explain run.csv --model datasheet.toml --report r.json --out-corrected corrected.csv --window-s 600
"""
NOTES = """The report (JSON), its evidence figure (.png) and, for an outlier population, every outlier
(.outliers.csv) are written; the console summary names each effect with its fitted parameters
and the score before and after (about 1: within what chance explains; docs/explain.md)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    from fogmon.explain.options import Options

    set_epilog(p, EXAMPLES, NOTES)
    default = Options()   # the library's defaults
    p.add_argument("recording", metavar="RECORDING",
                   help="replay log v1 (CSV: time_s, rate_dph in deg/h, aux columns; several axes: "
                   "rate_<axis>_dph columns, each axis explained unless --axis picks one, docs/explain.md), or a "
                   "ROS bag/MCAP, PX4 ULog, MDF4 or LAS file (docs/readers.md)")
    p.add_argument("--model", metavar="MODEL.toml",
                   help="sensor model TOML (docs/formats.md); without it a stationary IEEE-952 "
                   "baseline is fitted from the recording and the recording is explained against that")
    p.add_argument("--report", required=True, metavar="REPORT.json",
                   help="JSON report to write (docs/formats.md); a PNG of the "
                   "evidence is written next to it (same name, .png), and every outlier of an outlier population "
                   "(same name, .outliers.csv); with several axes one of each per axis (.<axis>.png, "
                   ".<axis>.outliers.csv)")
    p.add_argument("--rrd", metavar="OUT.rrd",
                   help="also write the evidence to this Rerun .rrd file")
    p.add_argument("--out-model", metavar="FITTED.toml",
                   help="write the model with the fitted effects added (TOML)")
    p.add_argument("--out-corrected", metavar="CORRECTED.csv",
                   help="write the recording with the fitted deterministic effects removed "
                   "(replay log v1)")
    p.add_argument("--window-s", type=positive, default=default.window_s,
                   metavar="SECONDS",
                   help="mismatch-map window in s, at least 16 samples and at most half the recording (default: "
                        "duration / 8); hop = window / 4, octave taus up to window / 4")
    p.add_argument("--bootstrap", type=number(8, MAX_BOOTSTRAP, integer=True), default=default.n_boot,
                   metavar="REPLICATES",
                   help=f"bootstrap replicates of the model, 8..{MAX_BOOTSTRAP} (default: 100 up to 1e5 samples, "
                   f"60 up to 4e5, else 40); a decision that would name an effect and lies within {SETTLE_SE:g} "
                   f"Monte Carlo standard errors of its threshold draws more, up to {MAX_GROWTH}x")
    p.add_argument("--alpha", type=number(0, 0.5, above=True), default=default.alpha,
                   metavar="PROBABILITY",
                   help=f"family-wise significance of the mismatch map, 0 < alpha <= 0.5 (default {default.alpha:g})")
    p.add_argument("--seed", type=number(0, integer=True), default=default.seed,
                   metavar="SEED",
                   help=f"seed of the bootstrap simulations, an integer >= 0 (default {default.seed})")
    p.add_argument("--max-effects", type=number(0, integer=True), default=default.max_effects,
                   metavar="COUNT",
                   help=f"most effects to add, >= 0 (default {default.max_effects}; 0: only locate the mismatches)")
    p.add_argument("--keep-motion", action="store_true",
                   help="analyse platform motion too: by default stretches where the rate moves far beyond "
                        "the sensor's noise with no rot_dps to say why (a turntable, a vehicle, a person) are "
                        "kept out of the analysis and reported as platform_motion warnings (docs/motion.md)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr and no console summary")
    add_reader_arguments(p, axis=True)
    add_export_argument(p)


class StageProgress:
    """``explain`` progress on ``stream`` (default stderr): each stage as a line, and on a
    terminal (``bar``, default: ``stream.isatty()``) a tqdm bar over counted steps."""

    def __init__(self, stream: TextIO | None = None, bar: bool | None = None):
        self.stream = stream or sys.stderr
        self.bar = self.stream.isatty() if bar is None else bar
        self._tq: Any = None  # a tqdm bar (tqdm is untyped) while one is shown

    def __call__(self, stage: str, done: int = 0, total: int = 0) -> None:
        if not total:
            self._end_bar()
            self.stream.write(f"fogmon explain: {stage}\n")
            self.stream.flush()
            return
        if not self.bar:
            return
        if self._tq is None or self._tq.total != total:
            from tqdm import tqdm

            self._end_bar()
            self._tq = tqdm(total=total, desc=f"  {stage}", file=self.stream, mininterval=0.2, dynamic_ncols=True)
        self._tq.update(done - self._tq.n)
        if done >= total:
            self._end_bar()

    def _end_bar(self) -> None:
        if self._tq is not None:
            self._tq.close()
            self._tq = None


def _options(args: argparse.Namespace):
    """explain's Options of the command line."""
    from fogmon.explain.options import Options

    return Options(window_s=args.window_s, n_boot=args.bootstrap, alpha=args.alpha, seed=args.seed,
                   max_effects=args.max_effects)


def run(args: argparse.Namespace) -> int:
    from fogmon.cli.output_options import check_command_outputs
    from fogmon.explain import report
    from fogmon.explain.axes import one_axis_model
    from fogmon.explain.explainer import check_inputs, explain, explain_without_model, without_motion
    from fogmon.sim.model import load_model
    from fogmon.sources.open import read_recording

    png = os.path.splitext(args.report)[0] + ".png"
    outliers_csv = report.outliers_path(args.report)
    check_command_outputs(args)
    export = export_request(args)
    progress = (lambda stage, done=0, total=0: None) if args.quiet else StageProgress()
    model = load_model(args.model) if args.model else None
    progress(f"reading {args.recording}")
    rec = read_recording(args.recording, source_options(args))
    if rec.axes and args.axis:
        rec = rec.for_axis(args.axis)
    if rec.axes:
        return _run_axes(args, rec, model, progress, export is not None)
    if model is not None:
        model = one_axis_model(model, rec, args.axis)
        check_inputs(rec, model, args.window_s, where=f"`model` {args.model}")   # before any work, naming the file
    motion: list[dict] = []
    as_recorded = rec
    if not args.keep_motion:
        progress("looking for platform motion")
        rec, motion = without_motion(rec)
    res = (explain(rec, model, _options(args), progress=progress) if model is not None
           else explain_without_model(rec, _options(args), progress))
    res.warnings[:0] = motion
    res.record_fit = report.record_fit(as_recorded, args.keep_motion)
    progress(f"writing {args.report}")
    held = _write_outliers(res, outliers_csv)
    rep = report.build_report(res, args.recording, args.model, os.path.basename(outliers_csv) if held else "")
    with written(args.report, "`report`") as tmp:
        report.write_report(rep, tmp)
    with written(png, "`report` (its PNG)") as tmp:
        report.write_png(res, tmp)
    if args.rrd:
        with written(args.rrd, "`rrd`", RRD_ERRORS) as tmp:
            report.write_rrd(res, tmp)
    _write_models(args, lambda m, c: report.write_outputs(res, m, c, outliers_csv if held else None))
    if export:
        write_export(*export, res.fitted.noise, f"{args.recording} (explain: the fitted model's noise)",
                     res.fitted.sample_rate_hz)
    if not args.quiet:
        print(report.console_summary(rep))
    return 0


#: what a failed Rerun file write raises (its file-writer thread gone: disk full, ...)
RRD_ERRORS = (OSError, RuntimeError)


def _write_outliers(res, path: str) -> int:
    """The outliers list next to the report (complete or not written); the rows written.
    Without an outliers effect, a list an earlier run left there is removed."""
    from fogmon.explain import report

    with written(path, "`report` (its outliers list)") as tmp:
        n = report.write_outliers(res, tmp)
    if not n:
        report.write_outliers(res, path)   # writes nothing: removes an earlier run's list
    return n


def _write_models(args: argparse.Namespace, write) -> None:
    """--out-model and --out-corrected by ``write(out_model, out_corrected)``, each
    complete or not written."""
    if args.out_model:
        with written(args.out_model, "`out_model`") as tmp:
            write(tmp, None)
    if args.out_corrected:
        with written(args.out_corrected, "`out_corrected`") as tmp:
            write(None, tmp)


def _run_axes(args: argparse.Namespace, rec, model, progress, export: bool) -> int:
    """``run`` for a recording with several axes (docs/explain.md, "Several axes"): every
    axis explained, the multi-axis report, per-axis PNG and outliers files next to it."""
    from fogmon.errors import FogmonError
    from fogmon.explain import report
    from fogmon.explain.axes import explain_axes
    from fogmon.explain.axes_report import (
        axes_console_summary,
        axis_file,
        build_axes_report,
        write_axes_outputs,
        write_axes_rrd,
    )

    if export:
        raise FogmonError(f"--export writes one axis's noise coefficients and {rec.name} has axes "
                          f"{', '.join(rec.axes)}: pick one with --axis NAME")
    pngs = {a: axis_file(args.report, a, ".png") for a in rec.axes}
    held = {a: axis_file(args.report, a, ".outliers.csv") for a in rec.axes}
    check_outputs({"`report`": args.report, **{f"`report` (its axis {a} PNG)": p for a, p in pngs.items()},
                   **{f"`report` (its axis {a} outliers list)": p for a, p in held.items()},
                   "`rrd`": args.rrd, "`out_model`": args.out_model, "`out_corrected`": args.out_corrected},
                  inputs=[args.recording, args.model, getattr(args, "dbc", None)])
    ares = explain_axes(rec, model, _options(args), keep_motion=args.keep_motion, progress=progress,
                        where=f"`model` {args.model}")
    progress(f"writing {args.report}")
    times = {a: os.path.basename(held[a]) for a, res in ares.results.items() if _write_outliers(res, held[a])}
    rep = build_axes_report(ares, args.recording, args.model, times)
    with written(args.report, "`report`") as tmp:
        report.write_report(rep, tmp)
    for a, res in ares.results.items():
        with written(pngs[a], f"`report` (its axis {a} PNG)") as tmp:
            report.write_png(res, tmp)
    if args.rrd:
        with written(args.rrd, "`rrd`", RRD_ERRORS) as tmp:
            write_axes_rrd(ares, tmp)
    _write_models(args, lambda m, c: write_axes_outputs(ares, m, c, {a: held[a] for a in times}))
    if not args.quiet:
        print(axes_console_summary(rep))
    return 0
