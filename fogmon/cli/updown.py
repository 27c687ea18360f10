"""``fogmon updown``: bias and scale-factor error of a single-axis gyro from two static
recordings against Earth rate, sensing axis up and then down."""
from __future__ import annotations

import argparse
import math
import os

import numpy as np

from fogmon.cli.source_options import add_reader_arguments, source_options
from fogmon.cli.values import number
from fogmon.errors import FogmonError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--up", required=True, metavar="UP.csv",
                   help="replay log (or another format, docs/formats.md), sensing axis pointing up")
    p.add_argument("--down", required=True, metavar="DOWN.csv",
                   help="replay log (or another format), sensing axis pointing down")
    p.add_argument("--lat-deg", required=True, type=number(-90, 90),
                   help="latitude of the test site, deg, -90..90 (south negative); near the equator the "
                        "vertical Earth rate is too small to calibrate a scale factor and the command says so")
    add_reader_arguments(p, axis=True)


def _mean_and_sigma(path: str, args) -> tuple[float, float, str]:
    from fogmon.davar.batch import oadev
    from fogmon.sources.open import read_recording

    rec = read_recording(path, source_options(args))
    if rec.axes:                                   # a three-axis IMU or multi-axis log: one gyro is calibrated
        if args.axis is None:
            raise FogmonError(f"{path}: has axes {', '.join(rec.axes)}; up/down calibrates one gyro: give --axis "
                              f"NAME (the axis pointing up and down)")
        rec = rec.for_axis(args.axis)
    res = oadev(rec.rate_dph, rec.sample_rate_hz, taus="octave")
    ok = np.isfinite(res.adev_dph)
    # std of the mean of the record ~ ADEV at the longest reliable tau (conservative)
    sigma = float(res.adev_dph[ok][-1]) if ok.any() else float(np.std(rec.rate_dph) / math.sqrt(len(rec)))
    return float(np.mean(rec.rate_dph)), sigma, rec.name


def run(args) -> int:
    from fogmon.methods.earthrate import updown_calibration

    if os.path.exists(args.up) and os.path.exists(args.down) and os.path.samefile(args.up, args.down):
        raise FogmonError(f"--up {args.up} and --down {args.down} are the same file")
    up, s_up, n_up = _mean_and_sigma(args.up, args)
    down, s_down, n_down = _mean_and_sigma(args.down, args)
    r = updown_calibration(up, down, args.lat_deg, max(s_up, s_down), (f"--up {args.up}", f"--down {args.down}"))
    print(f"up/down Earth-rate calibration at latitude {args.lat_deg:g} deg "
          f"(vertical Earth rate {r['earth_vertical_dph']:.4f} deg/h)")
    print(f"  mean output: up ({n_up}) {up:+.5f} deg/h, down ({n_down}) {down:+.5f} deg/h")
    print(f"  bias              {r['bias_dph']:+.5f} +/- {r['bias_sigma_dph']:.2g} deg/h")
    print(f"  scale-factor error {r['scale_factor_ppm']:+.1f} +/- {r['scale_factor_sigma_ppm']:.2g} ppm")
    return 0
