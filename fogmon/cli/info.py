"""``fogmon info FILE``: what a recording or log holds, one line per topic, channel,
signal or column: name, type, count, mean rate (Hz, from its time stamps), span (s) and
unit (CONTRACT section 3; fogmon.sources.open.file_info)."""
from __future__ import annotations

import argparse

from fogmon.cli.source_options import add_reader_arguments, source_options


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE", help="any file or folder fogmon reads: replay log (CSV, Parquet), raw "
                   "capture, CAN log (with --dbc: message names and units), ROS bag/MCAP, PX4 ULog, MDF4, LAS, "
                   "archive folder")
    p.add_argument("--tolerate-bad-rows", action="store_true", help="replay log: skip and count bad rows")
    p.add_argument("--protocol", help="a raw serial capture without a sidecar: its protocol (as fogmon replay)")
    add_reader_arguments(p)


def run(args: argparse.Namespace) -> int:
    from fogmon.sources.files.listing import format_entries
    from fogmon.sources.open import file_info

    for line in format_entries(file_info(args.file, source_options(args))):
        print(line)
    return 0
