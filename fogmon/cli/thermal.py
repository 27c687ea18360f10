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
from fogmon.cli.source_options import add_reader_arguments, source_options
from fogmon.cli.values import number, positive
from fogmon.errors import FogmonError
from fogmon.outputs import written

if TYPE_CHECKING:
    from fogmon.sim.model import Effect, SensorModel

#: Highest degree of K0(T): raw powers of deg C beyond it are ill-conditioned and over-fit
#: (the thermal literature uses 1..3).
MAX_DEGREE = 6


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="RECORDING.csv",
                   help="replay log with a temp_c column (deg C), or a PX4 ULog or LAS file with a "
                   "temperature (docs/formats.md)")
    p.add_argument("--degree", type=number(0, MAX_DEGREE, integer=True), default=2,
                   help=f"degree of K0(T), the bias-vs-temperature polynomial, 0..{MAX_DEGREE} (default 2)")
    p.add_argument("--smooth-s", type=number(0), help="trailing smoothing of temp_c before differencing, s, >= 0 "
                   "(default: the --model's thermal_drift value, else 10)")
    p.add_argument("--diff-step-s", type=positive, help="step of the 3-point backward differences, s, > 0 "
                   "(default: the --model's thermal_drift value, else 1)")
    p.add_argument("--average-s", type=positive, default=100.0,
                   help="block length for the peak-to-peak drift figure, s, at most half the recording (default 100)")
    p.add_argument("--model", metavar="BASE.toml", help="sensor model to add the calibrated thermal_drift effect to "
                   "(default: an empty model at the recording's sample rate)")
    p.add_argument("--out-model", metavar="OUT.toml", help="write the model with the thermal_drift effect")
    p.add_argument("--out-corrected", metavar="OUT.csv", help="write the recording with the predicted drift removed")
    add_reader_arguments(p, axis=True)


def run(args) -> int:
    from fogmon.cli.output_options import check_command_outputs
    from fogmon.formats.recording import pick_axes
    from fogmon.formats.replay_log import write_replay_log
    from fogmon.sim.model import Noise, SensorModel, load_model, save_model
    from fogmon.sources.open import read_recording

    check_command_outputs(args)
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
        with written(args.out_corrected, "`out_corrected`") as tmp:
            if len(axes) == 1:      # a one-axis recording, or one axis picked: a one-axis log
                one = recs[axes[0]]
                write_replay_log(tmp, one.t_s, corrected[axes[0]], one.aux, {**one.meta, **note})
            else:
                write_replay_log(tmp, rec.t_s, np.column_stack([corrected[a] for a in axes]),
                                 select_aux(rec.aux, rec.axes, axes), {**rec.meta, **note}, axes=axes)
        print(f"wrote {args.out_corrected}")
    return 0


def _filters(args, base, axis: str, rec) -> tuple[float, float]:
    """(smooth_s, diff_step_s) of ``axis``: the options, else the base model's
    thermal_drift acting on the axis, else 10 s and 1 s; checked against the record."""
    drifts = [e.params for e in base.effects if e.kind == "thermal_drift" and (not e.axes or axis in e.axes)]
    prior: dict = drifts[0] if drifts else {}
    smooth_s = args.smooth_s if args.smooth_s is not None else prior.get("smooth_s", 10.0)
    diff_step_s = args.diff_step_s if args.diff_step_s is not None else prior.get("diff_step_s", 1.0)
    settle_s = smooth_s + 2 * diff_step_s
    if settle_s >= rec.duration_s / 2:
        raise FogmonError(f"--smooth-s {smooth_s:g} + 2 x --diff-step-s {diff_step_s:g} = {settle_s:g} s of filter "
                          f"settling leaves less than half of the {rec.duration_s:g} s of {rec.name} to fit")
    if args.average_s > rec.duration_s / 2:
        raise FogmonError(f"--average-s {args.average_s:g} s: the peak-to-peak drift needs at least two blocks in "
                          f"the {rec.duration_s:g} s of {rec.name}")
    return smooth_s, diff_step_s


def _calibrate(rec, args, smooth_s: float, diff_step_s: float, prefix: str):
    """Calibrate one axis, print its coefficients and drift (lines starting with
    ``prefix``); (ThermalCalibration, corrected rate deg/h)."""
    from fogmon.methods.thermal import calibrate_thermal, correct_thermal, drift_peak_to_peak

    T = rec.aux["temp_c"]
    cal = calibrate_thermal(rec.t_s, rec.rate_dph, T, args.degree, smooth_s, diff_step_s)
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
    lines.append(f"  residual std {cal.residual_std_dph:.4g} deg/h per sample")
    change = (f"{before / after:.1f}x smaller" if after < before else
              f"{after / before:.1f}x larger: the fit does not reduce this drift" if before > 0 else "no drift")
    lines.append(f"peak-to-peak drift of {args.average_s:g} s averages: {before:.4g} deg/h -> {after:.4g} deg/h "
                 f"({change})")
    for line in lines:
        print(prefix + line)
    return cal, corrected


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
