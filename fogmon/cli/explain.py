"""`fogmon explain RECORDING.csv [--model MODEL.toml] --report REPORT.json [...]`:
locate where the recording's dynamic Allan deviation leaves what the model can
produce, name and fit the missing physics, show the fit improve (CONTRACT 3-4)."""
from __future__ import annotations

import argparse
import os

from fogmon.errors import FogmonError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", help="replay log v1 (CSV: time_s, rate_dph in deg/h, aux columns)")
    p.add_argument("--model", help="sensor model TOML (CONTRACT section 2); without it a stationary IEEE-952 "
                   "baseline is fitted from the recording and the recording is explained against that")
    p.add_argument("--report", required=True, help="JSON report to write (CONTRACT section 4); a PNG of the "
                   "evidence is written next to it (same name, .png)")
    p.add_argument("--rrd", help="also write the evidence to this Rerun .rrd file")
    p.add_argument("--out-model", help="write the model with the fitted effects added (TOML)")
    p.add_argument("--out-corrected", help="write the recording with the fitted deterministic effects removed "
                   "(replay log v1)")
    p.add_argument("--window-s", type=float, help="mismatch-map window in s (default: duration / 8); hop = "
                   "window / 4, octave taus up to window / 4")
    p.add_argument("--bootstrap", type=int, help="bootstrap replicates of the model (default: 100 up to 1e5 "
                   "samples, 60 up to 4e5, else 40)")
    p.add_argument("--alpha", type=float, default=0.01, help="family-wise significance of the mismatch map "
                   "(default 0.01)")
    p.add_argument("--seed", type=int, default=12345, help="seed of the bootstrap simulations (default 12345)")
    p.add_argument("--max-effects", type=int, default=8, help="most effects to add (default 8)")
    p.add_argument("--quiet", action="store_true", help="no console summary")


def run(args: argparse.Namespace) -> int:
    from fogmon.explain.baseline import baseline_model
    from fogmon.explain.explainer import Options, explain
    from fogmon.explain import report
    from fogmon.recording import read_replay_log
    from fogmon.sim.model import load_model

    if args.bootstrap is not None and args.bootstrap < 8:
        raise FogmonError(f"--bootstrap must be at least 8 replicates, got {args.bootstrap}")
    if not 0 < args.alpha < 0.5:
        raise FogmonError(f"--alpha must be between 0 and 0.5, got {args.alpha}")
    if args.window_s is not None and not args.window_s > 0:
        raise FogmonError(f"--window-s must be > 0 s, got {args.window_s}")
    for opt in ("report", "rrd", "out_model", "out_corrected"):
        path = getattr(args, opt)
        if path:
            d = os.path.dirname(os.path.abspath(path))
            if not os.path.isdir(d):
                raise FogmonError(f"--{opt.replace('_', '-')} {path}: directory {d} does not exist")
    rec = read_replay_log(args.recording)
    if args.model:
        model = load_model(args.model)
        baseline = False
    else:
        model = baseline_model(rec)
        baseline = True
    res = explain(rec, model, Options(window_s=args.window_s, n_boot=args.bootstrap, alpha=args.alpha,
                                      seed=args.seed, max_effects=args.max_effects), baseline=baseline)
    rep = report.build_report(res, args.recording, args.model)
    report.write_report(rep, args.report)
    report.write_png(res, os.path.splitext(args.report)[0] + ".png")
    if args.rrd:
        report.write_rrd(res, args.rrd)
    report.write_outputs(res, args.out_model, args.out_corrected)
    if not args.quiet:
        print(report.console_summary(rep))
    return 0
