"""`fogmon replay RECORDING`: stream a recording through the same pipeline as a live gyro
(source -> DAVAR -> noise fit -> Rerun + console summary), as fast as possible by default
or paced with --realtime."""
from __future__ import annotations

import argparse
import os

from fogmon.errors import FogmonError
from fogmon.pipeline import add_pipeline_arguments, run_pipeline

EPILOG = """examples:
  fogmon replay replay_logs/lasergyro_z_100hz.csv --rrd out/lasergyro.rrd
  fogmon replay run.csv --connect            # into a running viewer (start it with: rerun)
  fogmon replay run.csv --serve --realtime 10
  fogmon replay run.csv --window-s 600 --hop-s 60 --taus 8 --rrd out/run.rrd

Rates in deg/h, times in s, coefficients in IEEE-952 units (Q arcsec, N deg/sqrt(h),
B deg/h, K deg/h/sqrt(h), R deg/h^2). Without --rrd/--connect/--serve only the console
summary is printed. Exit code 0 on success, 2 on bad usage or input, 130 if interrupted."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EPILOG
    parser.add_argument("recording", metavar="RECORDING",
                        help="replay-log CSV (time_s, rate_dph, ...), raw serial capture (with --protocol) "
                             "or CAN log .asc/.blf/.trc/.csv/.log (with --dbc)")
    opener = _source_module()
    if opener is not None:
        opener.add_source_arguments(parser)
    else:
        parser.add_argument("--protocol", help="protocol of a raw serial capture (needs the drivers)")
        parser.add_argument("--dbc", help="DBC file describing the CAN frames (needs the drivers)")
    add_pipeline_arguments(parser)


def _source_module():
    try:
        from fogmon.sources import open as opener
    except ImportError:
        return None
    return opener


def open_source(args: argparse.Namespace):
    """The replay source for ``args.recording``."""
    path = args.recording
    if not os.path.exists(path):
        raise FogmonError(f"{path}: no such file")
    opener = _source_module()
    if opener is not None:
        return opener.open_replay_source(path, args)
    if getattr(args, "protocol", None) or getattr(args, "dbc", None):
        raise FogmonError("--protocol/--dbc replays need fogmon.sources.open, which is not installed")
    from fogmon.sources.replay import ReplayLogSource
    return ReplayLogSource(path, speed=getattr(args, "realtime", None))


def run(args: argparse.Namespace) -> int:
    source = open_source(args)
    summary = run_pipeline(source, args)
    return 130 if summary.interrupted else 0
