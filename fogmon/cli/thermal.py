"""``fogmon thermal``: calibrate the thermal-drift model of a gyro from a recording with
temperature (a chamber run), print the coefficients and the drift before/after, and
write the calibrated model and/or the corrected recording. A multi-axis recording is
calibrated axis by axis (``--axis`` picks some; each axis's temperature is ``temp_c_<axis>``
or the shared ``temp_c``), its lines prefixed by the axis; the model gets one
thermal_drift effect per axis (``axes = [<axis>]``) and the corrected recording keeps the
calibrated axes."""
from __future__ import annotations

import argparse
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from fogmon.block import select_aux
from fogmon.cli.helptext import set_epilog
from fogmon.cli.source_options import add_reader_arguments, source_options
from fogmon.cli.values import number, positive
from fogmon.errors import FogmonError
from fogmon.outputs import written

if TYPE_CHECKING:
    from fogmon.sim.model import Effect, SensorModel

#: Highest degree of K0(T): raw powers of deg C beyond it are ill-conditioned and over-fit
#: (the thermal literature uses 1..3).
MAX_DEGREE = 6


EXAMPLES = """
fogmon thermal replay_logs/sim_thermal_chamber_1hz.csv
fogmon thermal chamber.csv --model datasheet.toml --out-model calibrated.toml --out-corrected corrected.csv
fogmon thermal imu.csv --axis x,y --degree 3 --smooth-s 30 --diff-step-s 10
"""
NOTES = """Prints K0(T) (a polynomial in deg C), K1 (deg/h per degC/s) and K2 (deg/h per degC/s^2), each
with its 1-sigma error under the residual's own noise, the derivative filters (chosen by the
least residual unless given or in --model) and the peak-to-peak drift of --average-s averages
before and after the correction (docs/methods.md)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    set_epilog(p, EXAMPLES, NOTES)
    p.add_argument("recording", metavar="RECORDING.csv",
                   help="replay log with a temp_c column (deg C), or a PX4 ULog or LAS file with a "
                   "temperature (docs/formats.md)")
    p.add_argument("--degree", type=number(0, MAX_DEGREE, integer=True), default=2, metavar="DEGREE",
                   help=f"degree of K0(T), the bias-vs-temperature polynomial, 0..{MAX_DEGREE} (default 2)")
    p.add_argument("--smooth-s", type=number(0), metavar="SECONDS",
                   help="trailing smoothing of temp_c before differencing, s, >= 0 "
                   "(default: the --model's thermal_drift value, else chosen by the least residual)")
    p.add_argument("--diff-step-s", type=positive, metavar="SECONDS",
                   help="step of the 3-point backward differences, s, > 0 "
                   "(default: the --model's thermal_drift value, else chosen by the least residual)")
    p.add_argument("--average-s", type=positive, default=100.0, metavar="SECONDS",
                   help="block length for the peak-to-peak drift figure, s, at most half the recording (default 100)")
    p.add_argument("--model", metavar="BASE.toml", help="sensor model to add the calibrated thermal_drift effect to "
                   "(default: an empty model at the recording's sample rate)")
    p.add_argument("--out-model", metavar="CALIBRATED.toml", help="write the model with the thermal_drift effect")
    p.add_argument("--out-corrected", metavar="CORRECTED.csv",
                   help="write the recording with the predicted drift removed: CORRECTED.csv (replay log), or "
                   "CORRECTED.parquet for a Parquet replay log")
    add_reader_arguments(p, axis=True)


def run(args) -> int:
    from fogmon.cli.output_options import check_command_outputs
    from fogmon.formats.log_writer import check_log_suffix
    from fogmon.formats.recording import pick_axes
    from fogmon.sim.model import Noise, SensorModel, load_model, save_model
    from fogmon.sources.open import read_recording

    check_command_outputs(args)
    if args.out_corrected:
        check_log_suffix("`out_corrected`", args.out_corrected)
    base = load_model(args.model) if args.model else None
    rec = read_recording(args.recording, source_options(args))
    axes = pick_axes(rec.axes, args.axis, rec.name) or rec.axis_names()
    recs = {a: rec.for_axis(a) for a in axes}
    for a, one in recs.items():
        if "temp_c" not in one.aux:
            raise FogmonError(f"{rec.name}: no temp_c column{f' for axis {a} (temp_c or temp_c_{a})' if a else ''}; "
                              f"thermal calibration needs the sensor temperature")
    base = base or SensorModel(rec.sample_rate_hz, 0.0, Noise(), [])
    filters = {a: _filters(args, base, a, rec) for a in axes}     # every value checked before any fit
    cals, corrected = {}, {}
    for a, one in recs.items():
        cals[a], corrected[a] = _calibrate(one, args, *filters[a], prefix=f"{a}: " if a else "")
    if args.out_model:
        with written(args.out_model, "`out_model`") as tmp:
            save_model(with_calibration(base, {a: c.effect for a, c in cals.items()}, rec.axes), tmp)
        print(f"wrote {args.out_model}")
    if args.out_corrected:
        note = {"corrected": f"thermal_drift removed by fogmon thermal from {rec.name}"}
        if len(axes) == 1:      # a one-axis recording, or one axis picked: a one-axis log
            one = recs[axes[0]]
            _write_log(args.out_corrected, one.t_s, corrected[axes[0]], one.aux, {**one.meta, **note})
        else:
            _write_log(args.out_corrected, rec.t_s, np.column_stack([corrected[a] for a in axes]),
                       select_aux(rec.aux, rec.axes, axes), {**rec.meta, **note}, axes)
        print(f"wrote {args.out_corrected}")
    return 0


def _write_log(path: str, t_s, rate_dph, aux: dict, meta: dict, axes: tuple[str, ...] = ()) -> None:
    """The corrected recording as a replay log ``path`` in the format its suffix names
    (.csv or .parquet, as `fogmon sim` and `fogmon convert` write): complete or not at all."""
    from fogmon.formats.log_writer import LogWriter

    with LogWriter(path, list(aux), meta, axes, name="`out_corrected`") as w:
        w.write(t_s, rate_dph, aux)


def _filters(args, base, axis: str, rec) -> tuple[float | None, float | None, str]:
    """(smooth_s, diff_step_s, where from) of ``axis``: the options, else the base
    model's thermal_drift acting on the axis, else None (chosen by the fit); checked
    against the record."""
    drifts = [e.params for e in base.effects if e.kind == "thermal_drift" and (not e.axes or axis in e.axes)]
    prior: dict = drifts[0] if drifts else {}
    smooth_s = args.smooth_s if args.smooth_s is not None else prior.get("smooth_s")
    diff_step_s = args.diff_step_s if args.diff_step_s is not None else prior.get("diff_step_s")
    settle_s = (smooth_s or 0.0) + 2 * (diff_step_s or 0.0)
    if settle_s >= rec.duration_s / 2:
        terms = [f"--smooth-s {smooth_s:g}" if smooth_s is not None else "",
                 f"2 x --diff-step-s {diff_step_s:g}" if diff_step_s is not None else ""]
        raise FogmonError(f"{' + '.join(t for t in terms if t)} = {settle_s:g} s of filter settling leaves less "
                          f"than half of the {rec.duration_s:g} s of {rec.name} to fit")
    if args.average_s > rec.duration_s / 2:
        raise FogmonError(f"--average-s {args.average_s:g} s: the peak-to-peak drift needs at least two blocks in "
                          f"the {rec.duration_s:g} s of {rec.name}")
    given = {"options": args.smooth_s is not None or args.diff_step_s is not None, "--model": bool(prior)}
    return smooth_s, diff_step_s, ", ".join(k for k, v in given.items() if v)


def _calibrate(rec, args, smooth_s: float | None, diff_step_s: float | None, source: str, prefix: str):
    """Calibrate one axis, print its coefficients and drift (lines starting with
    ``prefix``); (ThermalCalibration, corrected rate deg/h)."""
    from fogmon.methods.thermal import calibrate_thermal, correct_thermal, drift_peak_to_peak

    T = rec.aux["temp_c"]
    cal = calibrate_thermal(rec.t_s, rec.rate_dph, T, args.degree, smooth_s, diff_step_s, where=rec.name)
    corrected = correct_thermal(rec.t_s, rec.rate_dph, T, cal.effect)
    before = drift_peak_to_peak(rec.t_s, rec.rate_dph, args.average_s)
    after = drift_peak_to_peak(rec.t_s, corrected, args.average_s)
    p, se = cal.effect.params, cal.stderr
    lines = [f"thermal drift model of {rec.name} ({len(rec)} samples, T {np.min(T):.1f}..{np.max(T):.1f} deg C)"]
    for i, (c, s) in enumerate(zip(p["k0_poly_dph"], se["k0_poly_dph"], strict=True)):
        lines.append(f"  K0 c{i:<6} {c:+.6g} +/- {s:.2g}  deg/h per degC^{i}")
    for k, unit in (("k1_pos", "deg/h per degC/s"), ("k1_neg", "deg/h per degC/s"),
                    ("k2_pos", "deg/h per degC/s^2"), ("k2_neg", "deg/h per degC/s^2")):
        lines.append(f"  {k:<9} {p[k]:+.6g} +/- {se[k]:.2g}  {unit}")
    chosen = [n for n, v in (("smooth_s", smooth_s), ("diff_step_s", diff_step_s)) if v is None]
    how = (f"{'both' if len(chosen) == 2 else chosen[0]} chosen: least residual of {cal.candidates} candidates"
           if chosen else "")
    how = "; ".join(x for x in (f"from {source}" if source else "", how) if x)
    lines.append(f"  filters   smooth_s {p['smooth_s']:g} s, diff_step_s {p['diff_step_s']:g} s ({how})")
    lines.append(f"  residual std {cal.residual_std_dph:.4g} deg/h per sample; +/- is 1 sigma under the residual noise "
                 f"{_levels(cal)}")
    change = (f"{before / after:.1f}x smaller" if after < before else
              f"{after / before:.1f}x larger: the fit does not reduce this drift" if before > 0 else "no drift")
    lines.append(f"peak-to-peak drift of {args.average_s:g} s averages: {before:.4g} deg/h -> {after:.4g} deg/h "
                 f"({change})")
    for line in lines:
        print(prefix + line)
    return cal, corrected


def _levels(cal) -> str:
    """The residual noise levels the standard errors assume, '<' for 95 % upper limits."""
    units = {"N_dpsh": "deg/sqrt(h)", "B_dph": "deg/h", "K_dphsh": "deg/h/sqrt(h)"}
    levels = " and ".join(f"{k[0]} {v:.3g} {units[k]}" for k, v in cal.residual_noise.items()
                          if k not in cal.upper_limits or v)
    limits = " or ".join(f"{k[0]} < {v:.3g} {units[k]}" for k, v in cal.upper_limits.items())
    return levels + (f" and {limits} (95 % upper limits, the larger error)" if limits else "")


def with_calibration(base: SensorModel, effects: dict[str, Effect], axes: tuple[str, ...]) -> SensorModel:
    """``base`` with the calibrated thermal_drift ``effects`` by axis ("" = a one-axis
    recording: the model's thermal_drift effects replaced by the one). Several axes: one
    effect per axis with ``axes = [<axis>]`` (docs/methods.md); a thermal_drift of
    ``base`` keeps acting only on the recording's axes not calibrated."""
    if "" in effects:
        kept = [e for e in base.effects if e.kind != "thermal_drift"]
        return replace(base, effects=kept + [effects[""]])
    kept = []
    for e in base.effects:
        rest = tuple(a for a in (e.axes or axes) if a not in effects) if e.kind == "thermal_drift" else e.axes
        if e.kind != "thermal_drift" or rest:
            kept.append(replace(e, axes=rest))
    return replace(base, effects=kept + [replace(eff, axes=(a,)) for a, eff in effects.items()])
