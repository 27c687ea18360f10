"""``fogmon updown``: bias and scale-factor error of a single-axis gyro from two static
recordings against Earth rate, sensing axis up and then down."""
from __future__ import annotations

import argparse
import math
import os

import numpy as np

from fogmon.cli.helptext import set_epilog
from fogmon.cli.source_options import add_reader_arguments, source_options
from fogmon.cli.values import number
from fogmon.errors import FogmonError

EXAMPLES = """
fogmon updown --up up.csv --down down.csv --lat-deg 52.38
fogmon updown --up up.ulg --down down.ulg --lat-deg -33.9 --axis z    # the z gyro of an IMU log
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    set_epilog(p, EXAMPLES)
    p.add_argument("--up", required=True, metavar="UP.csv",
                   help="replay log (or another format, docs/formats.md), sensing axis pointing up")
    p.add_argument("--down", required=True, metavar="DOWN.csv",
                   help="replay log (or another format), sensing axis pointing down")
    p.add_argument("--lat-deg", required=True, type=number(-90, 90), metavar="DEGREES",
                   help="latitude of the test site, deg, -90..90 (south negative); near the equator the "
                        "vertical Earth rate is too small to calibrate a scale factor and the command says so")
    add_reader_arguments(p, axis=True)


#: fewest samples a record may have: the Allan deviation that gives each mean's uncertainty
#: needs at least 4 (fogmon.davar.taus.tau_grid)
MIN_SAMPLES = 4


def _read(option: str, path: str, args):
    """The one-gyro recording ``option`` (``--up``/``--down``) names, checked before any
    work: one axis, its time base on the sample grid, enough samples."""
    from fogmon.sources.open import read_recording

    rec = read_recording(path, source_options(args))
    if rec.axes:                                   # a three-axis IMU or multi-axis log: one gyro is calibrated
        if args.axis is None:
            raise FogmonError(f"{path}: has axes {', '.join(rec.axes)}; up/down calibrates one gyro: give --axis "
                              f"NAME (the axis pointing up and down)")
        rec = rec.for_axis(args.axis)
    rec.grid_index()                               # off-grid samples, corrupt time stamps: named by line
    if len(rec) < MIN_SAMPLES:
        raise FogmonError(f"{option} {path}: {len(rec)} samples are too few for the uncertainty of its mean (an "
                          f"Allan deviation needs at least {MIN_SAMPLES})")
    return rec


def _mean_and_sigma(rec) -> tuple[float, float]:
    """The record's mean rate and its 1-sigma (deg/h): the ADEV at the longest tau with a
    value, on the sample grid (time gaps stay gaps: the Allan terms spanning one are left
    out, never joined across it)."""
    from fogmon.davar.batch import oadev

    blk = rec.to_block()
    res = oadev(blk.rate_dph, rec.sample_rate_hz, taus="octave", valid=blk.valid)
    ok = np.isfinite(res.adev_dph)
    # std of the mean of the record ~ ADEV at the longest reliable tau (conservative)
    sigma = float(res.adev_dph[ok][-1]) if ok.any() else float(np.std(rec.rate_dph) / math.sqrt(len(rec)))
    return float(np.mean(rec.rate_dph)), sigma


def run(args) -> int:
    from fogmon.methods.earthrate import updown_calibration

    if os.path.exists(args.up) and os.path.exists(args.down) and os.path.samefile(args.up, args.down):
        raise FogmonError(f"--up {args.up} and --down {args.down} are the same file")
    rec_up, rec_down = _read("--up", args.up, args), _read("--down", args.down, args)
    up, s_up = _mean_and_sigma(rec_up)
    down, s_down = _mean_and_sigma(rec_down)
    r = updown_calibration(up, down, args.lat_deg, max(s_up, s_down), (f"--up {args.up}", f"--down {args.down}"))
    print(f"up/down Earth-rate calibration at latitude {args.lat_deg:g} deg "
          f"(vertical Earth rate {r['earth_vertical_dph']:.4f} deg/h)")
    print(f"  mean output: up ({rec_up.name}) {up:+.5f} deg/h, down ({rec_down.name}) {down:+.5f} deg/h")
    print(f"  bias              {r['bias_dph']:+.5f} +/- {r['bias_sigma_dph']:.2g} deg/h (1 sigma)")
    print(f"  scale-factor error {r['scale_factor_ppm']:+.1f} +/- {r['scale_factor_sigma_ppm']:.2g} ppm (1 sigma)")
    return 0
