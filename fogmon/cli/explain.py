"""`fogmon explain RECORDING.csv [--model MODEL.toml] --report REPORT.json [...]`:
locate where the recording's dynamic Allan deviation leaves what the model can
produce, name and fit the missing physics, show the fit improve (docs/formats.md)."""
from __future__ import annotations

import argparse
import os
import sys
from typing import TextIO

from fogmon.cli.outputs import check_outputs
from fogmon.cli.values import number, positive

#: Most bootstrap replicates: each is one simulation of the whole recording, and beyond
#: this the Gumbel-fitted family-wise threshold no longer sharpens.
MAX_BOOTSTRAP = 10_000


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", help="replay log v1 (CSV: time_s, rate_dph in deg/h, aux columns)")
    p.add_argument("--model", help="sensor model TOML (docs/formats.md); without it a stationary IEEE-952 "
                   "baseline is fitted from the recording and the recording is explained against that")
    p.add_argument("--report", required=True, help="JSON report to write (docs/formats.md); a PNG of the "
                   "evidence is written next to it (same name, .png)")
    p.add_argument("--rrd", help="also write the evidence to this Rerun .rrd file")
    p.add_argument("--out-model", help="write the model with the fitted effects added (TOML)")
    p.add_argument("--out-corrected", help="write the recording with the fitted deterministic effects removed "
                   "(replay log v1)")
    p.add_argument("--window-s", type=positive, help="mismatch-map window in s, at least 16 samples and at most "
                   "half the recording (default: duration / 8); hop = window / 4, octave taus up to window / 4")
    p.add_argument("--bootstrap", type=number(8, MAX_BOOTSTRAP, integer=True),
                   help=f"bootstrap replicates of the model, 8..{MAX_BOOTSTRAP} (default: 100 up to 1e5 samples, "
                   "60 up to 4e5, else 40)")
    p.add_argument("--alpha", type=number(0, 0.5, above=True), default=0.01,
                   help="family-wise significance of the mismatch map, 0 < alpha <= 0.5 (default 0.01)")
    p.add_argument("--seed", type=number(0, integer=True), default=12345,
                   help="seed of the bootstrap simulations, an integer >= 0 (default 12345)")
    p.add_argument("--max-effects", type=number(0, integer=True), default=8,
                   help="most effects to add, >= 0 (default 8; 0: only locate the mismatches)")
    p.add_argument("--keep-motion", action="store_true",
                   help="analyse platform motion too: by default stretches where the rate moves far beyond "
                        "the sensor's noise with no rot_dps to say why (a turntable, a vehicle, a person) are "
                        "kept out of the analysis and reported as platform_motion warnings (docs/motion.md)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr and no console summary")


class StageProgress:
    """``explain`` progress on ``stream``: each stage as a line, and on a terminal
    (``bar``, default: ``stream.isatty()``) a one-line bar over counted steps."""

    WIDTH = 30

    def __init__(self, stream: TextIO | None = None, bar: bool | None = None):
        self.stream = stream or sys.stderr
        self.bar = self.stream.isatty() if bar is None else bar
        self._open = False

    def __call__(self, stage: str, done: int = 0, total: int = 0) -> None:
        if not total:
            self._end_bar()
            self.stream.write(f"fogmon explain: {stage}\n")
        elif self.bar:
            full = self.WIDTH * done // total
            self.stream.write(f"\r  [{'#' * full:<{self.WIDTH}}] {done}/{total} {stage}")
            self._open = True
            if done >= total:
                self._end_bar()
        self.stream.flush()

    def _end_bar(self) -> None:
        if self._open:
            self.stream.write("\n")
            self._open = False


def run(args: argparse.Namespace) -> int:
    from fogmon.explain.baseline import baseline_model
    from fogmon.explain.explainer import Options, explain, without_motion
    from fogmon.explain import report
    from fogmon.recording import read_replay_log
    from fogmon.sim.model import load_model

    png = os.path.splitext(args.report)[0] + ".png"
    check_outputs({"--report": args.report, "--report (its PNG)": png, "--rrd": args.rrd,
                   "--out-model": args.out_model, "--out-corrected": args.out_corrected},
                  inputs=[args.recording, args.model])
    progress = (lambda stage, done=0, total=0: None) if args.quiet else StageProgress()
    model = load_model(args.model) if args.model else None
    progress(f"reading {args.recording}")
    rec = read_replay_log(args.recording)
    motion = []
    if not args.keep_motion:
        progress("looking for platform motion")
        rec, motion = without_motion(rec)
    if model is None:
        progress("fitting a stationary IEEE-952 baseline model to the recording")
        model = baseline_model(rec)
    res = explain(rec, model, Options(window_s=args.window_s, n_boot=args.bootstrap, alpha=args.alpha,
                                      seed=args.seed, max_effects=args.max_effects),
                  baseline=args.model is None, progress=progress)
    res.warnings[:0] = motion
    progress(f"writing {args.report}")
    rep = report.build_report(res, args.recording, args.model)
    report.write_report(rep, args.report)
    report.write_png(res, png)
    if args.rrd:
        report.write_rrd(res, args.rrd)
    report.write_outputs(res, args.out_model, args.out_corrected)
    if not args.quiet:
        print(report.console_summary(rep))
    return 0
