"""`fogmon fit CURVE`: the IEEE-952 fit, with intervals and upper limits, of the
Allan-deviation curves another tool made: a CSV curve, imu_utils's data files,
allan_variance_ros's allan_variance.csv (fogmon.formats.curves, fogmon.davar.curve,
docs/exports.md); an accelerometer's as IEEE Std 1293 coefficients (fogmon.davar.accel)."""
from __future__ import annotations

import argparse

from fogmon.cli.export_options import add_export_argument, export_request
from fogmon.cli.helptext import set_epilog
from fogmon.cli.values import number, positive
from fogmon.export import write_export

EXAMPLES = """
fogmon fit curve.csv                                     # intervals at 68.3 % (1 sigma)
fogmon fit curve.csv --rate-hz 100 --record-s 7200 --confidence 0.95
fogmon fit curve.csv --export kalibr imu.yaml
fogmon fit data/data_xsens_acc_t.txt --rate-hz 100 --export kalibr imu.yaml   # imu_utils's curves
"""
NOTES = """CURVE: a CSV file with a header tau_s,adev_dph (s, deg/h; adev_ug or adev_mps2 for an
accelerometer) and optionally edf or n_terms, then one row per tau, increasing; '#' lines
are comments. Example:
  # from Stable32, overlapping ADEV of a 2 h record at 100 Hz
  tau_s,adev_dph,n_terms
  0.01,12.1,719999
Or another tool's output, told by the file: imu_utils's data_<name>_<gyr|acc>_<t|x|y|z>.txt
(any of them: the gyro and accelerometer curves of that sensor are read), allan_variance_ros's
allan_variance.csv (its accelerometer and gyro curves).

The fit needs the record's sample rate and length and the terms behind each tau; what the
curve does not state is assumed, and the output says what was assumed (docs/exports.md)."""

#: a curve longer than this shows only the taus the fit uses (one per octave)
MAX_ROWS_SHOWN = 100


def add_arguments(p: argparse.ArgumentParser) -> None:
    set_epilog(p, EXAMPLES, NOTES)
    p.add_argument("curve", metavar="CURVE", help="Allan-deviation curve: a CSV (columns tau_s (s), adev_dph "
                   "(deg/h) or adev_ug / adev_mps2, optional edf or n_terms), an imu_utils data file or an "
                   "allan_variance_ros allan_variance.csv")
    p.add_argument("--rate-hz", dest="sample_rate_hz", type=number(0, 1e6, above=True), metavar="HZ",
                   help="sample rate of the record behind the curve, Hz (default: what the file says, else 1 / the "
                        "first tau)")
    p.add_argument("--record-s", type=positive, metavar="SECONDS", help="length of that record, s (default: from "
                   "n_terms or the file's format, else assumed 4 x the largest tau)")
    p.add_argument("--confidence", type=number(0, 1, above=True, below=True), default=0.683, metavar="PROBABILITY",
                   help="two-sided confidence of the intervals, 0 < PROBABILITY < 1 (default 0.683 = 1 sigma)")
    add_export_argument(p)


def run(args: argparse.Namespace) -> int:
    from fogmon.cli import render
    from fogmon.cli.output_options import check_command_outputs
    from fogmon.davar.curve import CurveRowError
    from fogmon.errors import FogmonError
    from fogmon.formats.curves import read_curves

    check_command_outputs(args)
    export = export_request(args, [args.curve])
    cf = read_curves(args.curve)
    rate = args.sample_rate_hz or cf.rate_hz
    n, said = _record_samples(cf, args.record_s, rate)
    fits = []
    for c in cf.curves:
        try:
            fits.append(_fit(c, cf, rate, n, args.confidence))
        except FogmonError as e:
            what = f" ({c.sensor} {c.axis})" if c.axis else ""
            where = (f"{c.rows[e.index]}, column {e.column}{what}" if isinstance(e, CurveRowError) and c.rows
                     else f"{args.curve}{what}")
            raise FogmonError(f"{where}: {e.message}") from None
    r0 = fits[0][1]
    said += [s for s in fits[0][2] if s not in said]
    lines = [f"fogmon fit: {args.curve} ({cf.fmt}{', ' + str(len(cf.files)) + ' files' if len(cf.files) > 1 else ''}): "
             f"{len(cf.curves)} curve{'s' if len(cf.curves) > 1 else ''}, {len(r0.tau_s)} taus, "
             f"{r0.tau_s[0]:g}..{r0.tau_s[-1]:g} s; record {r0.n_samples} samples at {r0.sample_rate_hz:.10g} Hz = "
             f"{r0.n_samples / r0.sample_rate_hz:g} s"]
    lines += [f"  {s}" for s in cf.notes]
    lines += [f"  assumed: {render(s, 'fit')}" for s in said]
    for sensor in ("gyro", "accel"):
        group = [f for f in fits if f[0].sensor == sensor]
        if group:
            lines += _report(group, cf.fmt == "csv" and len(fits) == 1, args.confidence)
    if export:
        gyros = {c.axis: f for c, _, _, f in fits if c.sensor == "gyro"}
        accels = {c.axis or "-": f for c, _, _, f in fits if c.sensor == "accel"}
        # a rate the fit assumed (1 / the first tau) is said as assumed, never written as the IMU's update_rate
        assumed = "" if rate else f", the fit assuming {r0.sample_rate_hz:g} Hz (1 / the first tau; --rate-hz sets it)"
        write_export(*export, gyros.get("") if list(gyros) == [""] else gyros or None,
                     f"the curve{'s' if len(cf.files) > 1 else ''} {args.curve} ({cf.fmt}){assumed}",
                     rate, None, accels)
        lines.append(f"Wrote {export[1]} ({export[0]} export of the fit"
                     f"{'' if rate else '; update_rate left out: the sample rate was assumed, not stated'})")
    print("\n".join(lines))
    return 0


def _record_samples(cf, record_s: float | None, rate: float | None) -> tuple[int | None, list[str]]:
    """The record's samples: from ``record_s`` (s), else what the format implies (imu_utils:
    the middle of 2 M .. 4 M - 1; allan_variance_ros: 2 x the first tau with no value),
    else None (adev_from_curve assumes); and what was assumed."""
    tau0 = float(cf.curves[0].tau_s[0])
    fs = rate or 1.0 / tau0
    if record_s is not None:
        return int(round(record_s * fs)), []
    if cf.record_m is not None:
        n = 3 * cf.record_m
        return n, [f"record of {n} samples = {n / fs:g} s (imu_utils's largest averaging factor M = {cf.record_m} is "
                   f"the largest power of two <= N / 2, so N is 2 M .. 4 M - 1: the middle; `n_samples` sets it)"]
    if cf.no_value_tau_s is not None:
        n = int(round(2 * cf.no_value_tau_s * fs))
        return n, [f"record of {n} samples = {n / fs:g} s (2 x {cf.no_value_tau_s:g} s, the first tau without a "
                   f"value: at most that long; `n_samples` sets it)"]
    return None, []


def _fit(c, cf, rate: float | None, n: int | None, confidence: float):
    """(curve, AdevResult with the fit's intervals, assumptions, NoiseFit or AccelFit)."""
    from fogmon.davar.accel import AccelFit
    from fogmon.davar.curve import adev_from_curve, with_fit_intervals
    from fogmon.davar.fit import fit_noise

    result, said = adev_from_curve(c.tau_s, c.adev, sample_rate_hz=rate, n_terms=c.n_terms, edf=c.edf,
                                   n_samples=n, confidence=confidence, estimator=cf.estimator)
    fit = fit_noise(result, confidence=confidence)
    result = with_fit_intervals(result, fit, c.edf is not None or cf.estimator != "overlapping")
    return c, result, said, AccelFit.of(fit) if c.sensor == "accel" else fit


def _report(group: list, single: bool, confidence: float) -> list[str]:
    """ADEV tables and coefficients of one sensor's curves (``single``: one CSV curve, as
    a table of its own; else the axes side by side)."""
    from fogmon.davar.fit import octave_subset
    from fogmon.sinks.base import ACCEL_COEFFICIENTS, COEFFICIENTS
    from fogmon.sinks.console import (
        adev_axes_lines,
        adev_lines,
        coefficient_axes_lines,
        coefficient_lines,
        contradiction_lines,
        model_check,
    )

    accel = group[0][0].sensor == "accel"
    unit, names = ("ug", ACCEL_COEFFICIENTS) if accel else ("dph", COEFFICIENTS)
    r0 = group[0][1]
    rows = None
    if len(r0.tau_s) > MAX_ROWS_SHOWN:
        rows = octave_subset(r0.m, int(r0.m[-1]))
    shown = "" if rows is None else f"; {len(rows)} of the {len(r0.tau_s)} taus shown, one per octave"
    what = ("Accelerometer " if accel else "") + "Allan deviation" + (" (micro-g" if accel else " (deg/h")
    edf = "as stated" if group[0][0].edf is not None else "of the noise mixture the fit finds at each tau"
    lines = ["", f"{what}, {100 * confidence:.1f} % confidence bounds; EDF {edf}{shown}):"]
    terms = ("IEEE Std 1293 accelerometer noise coefficients" if accel else "IEEE-952 noise coefficients")
    if single:
        c, result, _, fit = group[0]
        lines += adev_lines(result, unit, rows)
        lines += ["", f"{terms} ({100 * confidence:.1f} % intervals):"] + coefficient_lines(fit, names)
        lines += [] if accel else contradiction_lines(fit)
        check = model_check(result, fit.noise if accel else fit)
        return lines + ([check] if check else [])
    lines += adev_axes_lines({c.axis: r for c, r, _, _ in group}, rows)
    lines += ["", f"{terms} per axis ({100 * confidence:.1f} % intervals; n/i: not identifiable, < its 95 % "
                  f"upper limit):"]
    lines += coefficient_axes_lines({c.axis: f for c, _, _, f in group}, names)
    for c, _, _, f in group:
        lines += [] if accel else [ln.replace("  ", f"  axis {c.axis}: ", 1) for ln in contradiction_lines(f)]
    for c, r, _, f in group:
        check = model_check(r, f.noise if accel else f)
        if check:
            lines.append(check.replace("model check:", f"model check ({'accelerometer' if accel else 'axis'} "
                                                       f"{c.axis}):"))
    return lines
