"""``fogmon thermal``: calibrate the thermal-drift model of a gyro from a recording with
temperature (a chamber run), print the coefficients and the drift before/after, and
write the calibrated model and/or the corrected recording."""
from __future__ import annotations

import argparse

import numpy as np

from fogmon.cli.outputs import check_outputs
from fogmon.cli.source_options import add_reader_arguments
from fogmon.cli.values import number, positive
from fogmon.errors import FogmonError

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
    from fogmon.methods.thermal import calibrate_thermal, correct_thermal, drift_peak_to_peak
    from fogmon.recording import write_replay_log
    from fogmon.sim.model import Noise, SensorModel, load_model, save_model
    from fogmon.sources.formats import read_recording

    check_outputs({"--out-model": args.out_model, "--out-corrected": args.out_corrected},
                  inputs=[args.recording, args.model])
    base = load_model(args.model) if args.model else None
    rec = read_recording(args.recording, args)
    if "temp_c" not in rec.aux:
        raise FogmonError(f"{rec.name}: no temp_c column; thermal calibration needs the sensor temperature")
    base = base or SensorModel(rec.sample_rate_hz, 0.0, Noise(), [])
    prior = next((e.params for e in base.effects if e.kind == "thermal_drift"), {})
    smooth_s = args.smooth_s if args.smooth_s is not None else prior.get("smooth_s", 10.0)
    diff_step_s = args.diff_step_s if args.diff_step_s is not None else prior.get("diff_step_s", 1.0)
    settle_s = smooth_s + 2 * diff_step_s
    if settle_s >= rec.duration_s / 2:
        raise FogmonError(f"--smooth-s {smooth_s:g} + 2 x --diff-step-s {diff_step_s:g} = {settle_s:g} s of filter "
                          f"settling leaves less than half of the {rec.duration_s:g} s of {rec.name} to fit")
    if args.average_s > rec.duration_s / 2:
        raise FogmonError(f"--average-s {args.average_s:g} s: the peak-to-peak drift needs at least two blocks in "
                          f"the {rec.duration_s:g} s of {rec.name}")
    T = rec.aux["temp_c"]
    cal = calibrate_thermal(rec.t_s, rec.rate_dph, T, args.degree, smooth_s, diff_step_s)
    corrected = correct_thermal(rec.t_s, rec.rate_dph, T, cal.effect)
    before = drift_peak_to_peak(rec.t_s, rec.rate_dph, args.average_s)
    after = drift_peak_to_peak(rec.t_s, corrected, args.average_s)
    p, se = cal.effect.params, cal.stderr
    print(f"thermal drift model of {rec.name} ({len(rec)} samples, T {np.min(T):.1f}..{np.max(T):.1f} deg C)")
    for i, (c, s) in enumerate(zip(p["k0_poly_dph"], se["k0_poly_dph"], strict=True)):
        print(f"  K0 c{i:<6} {c:+.6g} +/- {s:.2g}  deg/h per degC^{i}")
    for k, unit in (("k1_pos", "deg/h per degC/s"), ("k1_neg", "deg/h per degC/s"),
                    ("k2_pos", "deg/h per degC/s^2"), ("k2_neg", "deg/h per degC/s^2")):
        print(f"  {k:<9} {p[k]:+.6g} +/- {se[k]:.2g}  {unit}")
    print(f"  residual std {cal.residual_std_dph:.4g} deg/h per sample")
    change = (f"{before / after:.1f}x smaller" if after < before else
              f"{after / before:.1f}x larger: the fit does not reduce this drift" if before > 0 else "no drift")
    print(f"peak-to-peak drift of {args.average_s:g} s averages: {before:.4g} deg/h -> {after:.4g} deg/h ({change})")
    if args.out_model:
        base.effects = [e for e in base.effects if e.kind != "thermal_drift"] + [cal.effect]
        save_model(base, args.out_model)
        print(f"wrote {args.out_model}")
    if args.out_corrected:
        meta = dict(rec.meta, corrected=f"thermal_drift removed by fogmon thermal from {rec.name}")
        write_replay_log(args.out_corrected, rec.t_s, corrected, rec.aux, meta)
        print(f"wrote {args.out_corrected}")
    return 0
