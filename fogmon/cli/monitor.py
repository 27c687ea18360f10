"""`fogmon monitor --serial PORT | --can CHANNEL`: monitor a live gyro. Every decoded
sample and the raw input are archived (in a new time-stamped folder in ``--archive DIR``,
default the current folder) so nothing is lost, while DAVAR, the noise fit and Rerun run
as in a replay."""
from __future__ import annotations

import argparse
import os
import sys

from fogmon.cli.output_options import check_command_outputs
from fogmon.cli.pipeline_options import add_pipeline_arguments, build_sinks, output_errors, pipeline_config
from fogmon.cli.source_options import add_source_arguments, source_options
from fogmon.cli.values import positive
from fogmon.errors import FogmonError
from fogmon.formats.archive import archive_files, default_archive_dir
from fogmon.pipeline import Pipeline
from fogmon.sinks.archive import Archive
from fogmon.sinks.base import Summary
from fogmon.sinks.parquet_pieces import ROW_GROUP_S
from fogmon.sources.open import open_live_source

EPILOG = """examples:
  fogmon monitor --serial /dev/ttyUSB0 --protocol kvh-a --connect        # into a running `rerun` viewer
  fogmon monitor --serial /dev/ttyUSB0 --protocol dsp3000 --serve --duration-s 3600
  fogmon monitor --can can0 --dbc gyro.dbc --rrd run.rrd --archive runs/

Stop with Ctrl-C, SIGTERM or SIGHUP (or --duration-s): the archive and the .rrd are
closed cleanly and the summary printed. Each run archives into a new folder
DIR/fogmon-archive-YYYYmmddTHHMMSSZ (DIR: --archive, default the current folder; it must
exist), in pieces of --rotate-s s (default one hour): samples-0001.csv, ... (replay logs)
and the raw input (raw-0001.bin + .json or frames-0001.asc + .json); `fogmon replay
DIR/fogmon-archive-...` replays them all as one recording, `fogmon replay
DIR/fogmon-archive-.../samples-0002.csv` one piece. Rates in deg/h, times in s,
coefficients in IEEE-952 units. Exit code 0 on success (also after Ctrl-C, SIGTERM or
SIGHUP: stopping is how a live run ends), 1 when no sample arrived from the device (one
line says what did arrive, if anything; an archive folder the run created is removed
when nothing at all arrived) or when an output could not be written (a full disk: the
run stops, the summary is printed, the archive keeps every whole row written), 2 on bad
usage or input."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EPILOG
    add_source_arguments(parser, mode="live")
    parser.add_argument("--archive", metavar="DIR",
                        help="existing folder in which each run makes its archive folder "
                             "fogmon-archive-YYYYmmddTHHMMSSZ (samples-NNNN.csv + raw capture pieces; default: the "
                             "current folder)")
    parser.add_argument("--archive-format", choices=("csv", "parquet"), default="csv",
                        help="decoded samples as replay-log CSV pieces samples-NNNN.csv (default) or Parquet "
                             "pieces samples-NNNN.parquet written in row groups as data arrives (a SIGKILL loses at "
                             "most the row group being filled, see --row-group-s); the raw capture is kept either way")
    parser.add_argument("--row-group-s", type=positive, default=ROW_GROUP_S, metavar="S",
                        help=f"--archive-format parquet: s of samples per row group (default {ROW_GROUP_S:g})")
    add_pipeline_arguments(parser, replay=False)


def run(args: argparse.Namespace) -> int:
    from fogmon.cli import render

    check_command_outputs(args)
    parent = args.archive or "."
    if archive_files(parent):
        raise FogmonError(f"`archive` {parent}: is an archive folder; give the folder to make the run's archive "
                          f"folder in")
    source = open_live_source(source_options(args))
    try:
        archive = Archive(default_archive_dir(parent), source, samples_format=args.archive_format,
                          row_group_s=args.row_group_s, duration_s=args.duration_s)
    except BaseException:
        source.close()
        raise
    sinks: list = []
    try:
        pipeline = Pipeline(source, pipeline_config(args))  # options checked before any output is opened
        sinks = [*build_sinks(args), archive]
        summary = pipeline.run(sinks)
    finally:
        archive.close()   # also when the run never started; a folder it created and left empty goes
    failed = output_errors(sinks)
    for e in failed:      # after the summary: what could not be written, and where
        print(f"fogmon monitor: error: {render(e, 'monitor')}", file=sys.stderr)
    if not summary.n_samples:
        print(f"fogmon monitor: {nothing_received(summary, archive)}", file=sys.stderr)
        return 1
    return 1 if failed else 0


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
