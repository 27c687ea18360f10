"""`fogmon fit CURVE.csv`: the IEEE-952 fit, with intervals and upper limits, of an
Allan-deviation curve made by another tool (fogmon.davar.curve, docs/exports.md)."""
from __future__ import annotations

import argparse

from fogmon.cli.export_options import add_export_argument, export_request
from fogmon.cli.values import number, positive
from fogmon.export import write_export

EPILOG = """CURVE.csv: a header line tau_s,adev_dph (s, deg/h) and optionally edf or n_terms, then one
row per tau, increasing; '#' lines are comments. Example:
  # from Stable32, overlapping ADEV of a 2 h record at 100 Hz
  tau_s,adev_dph,n_terms
  0.01,12.1,719999

The fit needs the record's sample rate and length and the terms behind each tau; what the
curve does not state is assumed, and the output says what was assumed (docs/exports.md).
  fogmon fit curve.csv --export kalibr imu.yaml
Exit code 0 on success, 2 on bad usage or input."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = EPILOG
    p.add_argument("curve", metavar="CURVE.csv", help="Allan-deviation curve: columns tau_s (s), adev_dph (deg/h), "
                   "optional edf or n_terms")
    p.add_argument("--rate-hz", dest="sample_rate_hz", type=number(0, 1e6, above=True), metavar="HZ",
                   help="sample rate of the record behind the curve, Hz (default: 1 / the first tau)")
    p.add_argument("--record-s", type=positive, metavar="S", help="length of that record, s (default: from "
                   "n_terms, else assumed 4 x the largest tau)")
    p.add_argument("--confidence", type=number(0, 1, above=True), default=0.683, metavar="C",
                   help="two-sided confidence of the intervals, 0 < C < 1 (default 0.683 = 1 sigma)")
    add_export_argument(p)


def run(args: argparse.Namespace) -> int:
    from fogmon.cli import render
    from fogmon.davar.curve import adev_from_curve, read_curve_csv, with_fit_intervals
    from fogmon.davar.fit import fit_noise
    from fogmon.errors import FogmonError
    from fogmon.sinks.console import adev_lines, coefficient_lines, model_check

    if not args.confidence < 1:
        raise FogmonError(f"--confidence must be below 1, got {args.confidence:g}")
    export = export_request(args, [args.curve])
    cols, _ = read_curve_csv(args.curve)
    n = None
    if args.record_s is not None:
        rate = args.sample_rate_hz or 1.0 / float(cols["tau_s"][0])
        n = int(round(args.record_s * rate))
    try:
        result, said = adev_from_curve(cols["tau_s"], cols["adev_dph"], sample_rate_hz=args.sample_rate_hz,
                                       n_terms=cols.get("n_terms"), edf=cols.get("edf"), n_samples=n,
                                       confidence=args.confidence)
    except FogmonError as e:
        raise FogmonError(f"{args.curve}: {e.message}") from None
    fit = fit_noise(result, confidence=args.confidence)
    result = with_fit_intervals(result, fit, "edf" in cols)
    lines = [
        f"fogmon fit: {args.curve}: {len(result.tau_s)} taus, {result.tau_s[0]:g}..{result.tau_s[-1]:g} s; "
        f"record {result.n_samples} samples at {result.sample_rate_hz:g} Hz = "
        f"{result.n_samples / result.sample_rate_hz:g} s"
    ]
    lines += [f"  assumed: {render(s, 'fit')}" for s in said]
    lines += ["", f"Allan deviation ({100 * args.confidence:.1f} % confidence bounds; EDF "
              f"{'as stated' if 'edf' in cols else 'of the noise mixture the fit finds at each tau'}):"]
    lines += adev_lines(result)
    lines += ["", f"IEEE-952 noise coefficients ({100 * fit.confidence:.1f} % intervals):"] + coefficient_lines(fit)
    check = model_check(result, fit)
    if check:
        lines.append(check)
    if export:
        write_export(*export, fit, f"the curve {args.curve}", args.sample_rate_hz)
        lines.append(f"Wrote {export[1]} ({export[0]} export of the fit)")
    print("\n".join(lines))
    return 0
