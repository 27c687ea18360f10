"""`fogmon convert IN OUT.parquet`: a recording (replay-log CSV, Parquet log, raw serial
capture, CAN log, archive folder) as a Parquet replay log (fogmon.formats.parquet_log), or as
a replay-log CSV when OUT ends in .csv. The samples are those `fogmon replay IN` would
analyse: decoded, on their grid, valid ones only (gaps stay time gaps)."""
from __future__ import annotations

import argparse
import itertools
import os

import numpy as np

from fogmon.cli.helptext import set_epilog
from fogmon.errors import FogmonError

EXAMPLES = """
fogmon convert run.csv run.parquet
fogmon convert raw-0001.bin run.parquet                  # decoder options from raw-0001.bin.json
fogmon convert frames.asc run.parquet --dbc gyro.dbc
fogmon convert runs/fogmon-archive-20261121T080000Z week.parquet
fogmon convert run.parquet run.csv
"""
NOTES = """The Parquet file keeps the replay-log columns (time_s s, rate_dph deg/h or one
rate_<axis>_dph per axis, aux channels) as float64 in row groups of 65,536 rows, and
in its key-value metadata (key "fogmon", JSON) the replay-log metadata, the units, the
source and, for a raw capture, its decoder options and counters. A multi-axis recording
keeps its axes (--axis picks some); a sample time where some axis is invalid is left
out (a row holds every axis) and counted. Every sample not written is counted: invalid
or lost ones (gaps, rows skipped with --tolerate-bad-rows, rates beyond the plausibility
gate; they read back as time gaps) with the source's counters saying why, on the console
and in a Parquet output's counters. An output without any sample is refused (exit 2,
no file)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from fogmon.cli.source_options import add_reader_arguments, add_source_arguments

    set_epilog(parser, EXAMPLES, NOTES)
    parser.add_argument("input", metavar="RECORDING",
                        help="replay-log CSV, Parquet log, raw serial capture (sidecar or "
                        "--protocol), CAN log (--dbc) or archive folder")
    parser.add_argument("output", metavar="OUT.parquet",
                        help="OUT.parquet (Parquet replay log) or OUT.csv (replay log)")
    add_source_arguments(parser, mode="replay")
    add_reader_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from fogmon.cli.output_options import check_command_outputs
    from fogmon.cli.source_options import source_options
    from fogmon.formats.log_writer import check_log_suffix
    from fogmon.sources.open import open_replay_source

    check_command_outputs(args)
    check_log_suffix("OUT", args.output)
    source = open_replay_source(args.input, source_options(args))
    if getattr(source, "n_samples", None) is None:
        raise FogmonError(f"{args.input}: an endless source (a sensor model) cannot be converted; "
                          f"use `fogmon sim --out`")
    try:
        n, invalid, without_aux, partial = _convert(source, args.input, args.output)
    finally:
        source.close()
    print(f"fogmon convert: wrote {n} samples at {source.sample_rate_hz:g} Hz from {source.name} to {args.output}"
          + (f"; {invalid} invalid or lost samples left out{_why(source.counters)}" if invalid else "")
          + (f"; {without_aux} valid samples without aux values (not yet known) left out" if without_aux else "")
          + (f"; {partial} samples with only some axes valid left out" if partial else ""))
    return 0


#: the source counters that say why samples of the grid are invalid or lost (docs/sources.md, Counters)
LOSS_COUNTERS = ("samples_missing", "skipped_rows", "invalid_samples", "implausible_samples")


def _why(counters: dict) -> str:
    """" (samples_missing 3, implausible_samples 5)": the source's nonzero loss counters."""
    named = [f"{k} {counters[k]}" for k in LOSS_COUNTERS if counters.get(k)]
    return f" ({', '.join(named)})" if named else ""


def _convert(source, input_path: str, output: str) -> tuple[int, int, int, int]:
    """Write ``source``'s valid samples to ``output`` (a Parquet log for .parquet, else
    a replay-log CSV; fogmon.formats.log_writer); after the first block that writes rows,
    the free space is checked against the source's samples at the bytes per row measured on it; no
    half-written output on any error, and none without a sample (FogmonError saying
    why). Returns the samples written and those left out: invalid or lost (no axis
    valid: time gaps in the output), valid without aux values, with only some axes
    valid; a Parquet output keeps these counts with the source's counters."""
    from fogmon.formats.capture import read_sidecar
    from fogmon.formats.log_writer import LogWriter
    from fogmon.outputs import check_space
    from fogmon.sinks.archive import replay_rows

    blocks = source.blocks()
    first = next(blocks, None)
    aux_names = list(first.aux) if first is not None else list(getattr(source, "aux_names", []))
    axes = first.axes if first is not None else source.axes
    side = read_sidecar(input_path) if os.path.isfile(input_path) else None
    extra = {"source": source.name, **({"sidecar": side} if side else {})}
    without_aux = partial = seen = invalid = 0
    sized = False
    with LogWriter(output, aux_names, _replay_meta(source), axes, extra, name="OUT") as w:   # no half-written output
        for b in itertools.chain([first] if first is not None else [], blocks):
            keep, b_partial, b_without_aux = replay_rows(b)
            without_aux += b_without_aux
            partial += b_partial
            invalid += len(b) - int(np.count_nonzero(keep)) - b_without_aux - b_partial
            seen += len(b)
            w.write(b.t_s[keep], b.rate_dph[keep], {k: a[keep] for k, a in b.aux.items()})
            if w.rows and not sized:            # the first block with rows: will the rest fit?
                sized = True
                left = max(source.n_samples - seen, 0) * w.rows / seen
                check_space("OUT", output, left * w.bytes_per_row,
                            f"{left:.3g} more rows of {w.bytes_per_row:.1f} bytes (measured on the first {w.rows})")
        if not w.rows:
            gate = "; `max_rate_dph` sets the plausibility gate" if source.counters.get("implausible_samples") else ""
            why = [f"{n} {what}" for n, what in ((invalid, f"invalid or lost{_why(source.counters)}"),
                                                (without_aux, "without aux values"),
                                                (partial, "with only some axes valid")) if n]
            raise FogmonError(f"{input_path}: no sample to write, nothing written to OUT {output}: of {seen} "
                              f"samples, {', '.join(why) or 'none'}{gate}")
        w.close(counters={**source.counters, "rows_written": w.rows, "invalid_samples_left_out": invalid,
                          "rows_without_aux": without_aux, **({"partial_samples_dropped": partial} if axes else {})})
    return w.rows, invalid, without_aux, partial


def _replay_meta(source) -> dict[str, str]:
    """The output's replay-log metadata: the source's, with its sample rate (Hz) and sensor."""
    src_meta = getattr(source, "meta", {}) or {}
    return {"sample_rate_hz": f"{source.sample_rate_hz:.12g}", "sensor": src_meta.get("sensor", source.name),
            **{k: v for k, v in src_meta.items() if k not in ("sample_rate_hz", "sensor")}}
