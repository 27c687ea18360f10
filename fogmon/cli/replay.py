"""`fogmon replay RECORDING`: stream a recording through the same pipeline as a live gyro
(source -> DAVAR -> noise fit -> Rerun + console summary), as fast as possible by default
or paced with --realtime."""
from __future__ import annotations

import argparse

from fogmon.pipeline import add_pipeline_arguments, run_pipeline
from fogmon.sources.open import add_source_arguments, open_replay_source

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
    add_source_arguments(parser, mode="replay")
    add_pipeline_arguments(parser)


def run(args: argparse.Namespace) -> int:
    source = open_replay_source(args.recording, args)
    summary = run_pipeline(source, args)
    return 130 if summary.interrupted else 0
