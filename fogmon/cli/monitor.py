"""`fogmon monitor --serial PORT | --can CHANNEL`: monitor a live gyro. Every decoded
sample and the raw input are archived (``--archive DIR``, default a new time-stamped
folder) so nothing is lost, while DAVAR, the noise fit and Rerun run as in a replay."""
from __future__ import annotations

import argparse
import os
import sys

from fogmon.cli.helptext import set_epilog
from fogmon.cli.pipeline_options import add_pipeline_arguments, build_sinks, pipeline_config
from fogmon.cli.source_options import add_source_arguments, source_options
from fogmon.cli.values import positive
from fogmon.formats.archive import default_archive_dir
from fogmon.pipeline import Pipeline
from fogmon.sinks.archive import Archive
from fogmon.sinks.base import Summary
from fogmon.sinks.parquet_pieces import ROW_GROUP_S
from fogmon.sources.open import open_live_source

EXAMPLES = """
fogmon monitor --serial /dev/ttyUSB0 --protocol kvh-a --connect        # into a running `rerun` viewer
fogmon monitor --serial /dev/ttyUSB0 --protocol dsp3000 --serve --duration-s 3600
fogmon monitor --can can0 --dbc gyro.dbc --rrd out/run.rrd --archive runs/2026-11-21
fogmon monitor --serial /dev/ttyACM0 --protocol lines --columns seq:65536,rate_dps,temp_c --rate-hz 200
"""
NOTES = """Stop with Ctrl-C, SIGTERM or SIGHUP (or --duration-s): the archive and the .rrd are
closed cleanly and the summary printed. The archive holds pieces of --rotate-s s
(default one hour): samples-0001.csv, ... (replay logs) and the raw input (raw-0001.bin
+ .json or frames-0001.asc + .json); `fogmon replay DIR` replays them all as one
recording, `fogmon replay DIR/samples-0002.csv` one piece. Rates in deg/h, times in s,
coefficients in IEEE-952 units."""
EXIT_CODES = """exit codes:
  0   success, also after Ctrl-C, SIGTERM or SIGHUP (stopping is how a live run ends)
  1   no sample arrived from the device (one line says what did arrive, if anything; an
      archive folder the run created is removed when nothing at all arrived)
  2   bad usage or input: one line names the option or the file (checked before the port opens)"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    set_epilog(parser, EXAMPLES, NOTES, EXIT_CODES)
    add_source_arguments(parser, mode="live")
    parser.add_argument("--archive", metavar="DIR",
                        help="folder for the archive (samples-NNNN.csv + raw capture pieces); default: a new "
                             "fogmon-archive-YYYYmmddTHHMMSSZ folder in the current directory")
    parser.add_argument("--archive-format", choices=("csv", "parquet"), default="csv",
                        help="decoded samples as replay-log CSV pieces samples-NNNN.csv (default) or Parquet "
                             "pieces samples-NNNN.parquet written in row groups as data arrives (a SIGKILL loses at "
                             "most the row group being filled, see --row-group-s); the raw capture is kept either way")
    parser.add_argument("--row-group-s", type=positive, default=ROW_GROUP_S, metavar="SECONDS",
                        help=f"--archive-format parquet: s of samples per row group (default {ROW_GROUP_S:g})")
    add_pipeline_arguments(parser, replay=False)


def run(args: argparse.Namespace) -> int:
    source = open_live_source(source_options(args))
    archive = Archive(args.archive or default_archive_dir("."), source, samples_format=args.archive_format,
                      row_group_s=args.row_group_s)
    try:
        pipeline = Pipeline(source, pipeline_config(args))  # options checked before any output is opened
        summary = pipeline.run([*build_sinks(args), archive])
    finally:
        archive.close()   # also when the run never started; a folder it created and left empty goes
    if not summary.n_samples:
        print(f"fogmon monitor: {nothing_received(summary, archive)}", file=sys.stderr)
        return 1
    return 0


def nothing_received(summary: Summary, archive: Archive) -> str:
    """The one line for a run that gave no sample: what did arrive, and where it is."""
    c = archive.counters
    removed = not os.path.isdir(archive.directory)
    what = (f"{c['raw_frames']:,} CAN frames" if c["raw_frames"] else
            f"{c['raw_bytes']:,} bytes" if c["raw_bytes"] else "")
    src = f"{summary.source_name} in {summary.source_wall_s:.1f} s"
    if not what:
        return f"nothing was received from {src}" + ("; no archive written" if removed else "")
    seen = ", ".join(f"{k} {v:,}" for k, v in summary.counters.items() if v)
    return (f"no sample decoded from {src} although {what} arrived ({seen or 'no frame recognised'}): "
            f"check --protocol/--baud or --dbc/--can-message; the raw input is in {archive.directory}")
