"""Opening a live or replayed source from SourceOptions: the one place that knows which
reader handles which device, file or folder (docs/sources.md). Used by ``fogmon monitor``
and ``fogmon replay``."""
from __future__ import annotations

import os
import re

from fogmon.errors import FogmonError
from fogmon.sources import plausibility as pl
from fogmon.sources.base import Source
from fogmon.sources.codecs import DEFAULTS, PROTOCOLS, make_codec
from fogmon.sources.options import SourceOptions

CAN_LOG_SUFFIXES = (".asc", ".blf", ".trc", ".log", ".mf4")


def open_live_source(opts: SourceOptions) -> Source:
    """The live source named by ``--serial`` or ``--can`` (exactly one)."""
    if opts.serial and not opts.can:
        from fogmon.sources.serial_source import SerialSource
        o = opts.codec_options()
        protocol = o.pop("protocol") or "kvh-a"
        codec = make_codec(protocol, **{k: v for k, v in o.items() if v is not None})
        return SerialSource(opts.serial, opts.baud or DEFAULTS[protocol][0], codec)
    if opts.can and not opts.serial:
        from fogmon.sources.can_source import CanSource, load_dbc
        if not opts.dbc:
            raise FogmonError("--can needs --dbc F describing the gyro's frames (example: "
                              "fogmon/data/gyro_example.dbc)")
        return CanSource(opts.can, opts.interface, load_dbc(opts.dbc), bitrate=opts.can_bitrate,
                         dbc_path=opts.dbc, **opts.can_options())
    raise FogmonError("give exactly one of --serial PORT or --can CHANNEL")


def _sniff(path: str) -> str:
    """'replay-log', 'can-csv' or 'other' from the first non-empty line."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError as e:
        raise FogmonError(f"{path}: cannot read: {e.strerror}") from None
    for raw in head.splitlines():
        s = raw.strip()
        if not s:
            continue
        if s.startswith(b"# fogmon replay log") or (b"time_s" in s and re.search(rb"rate_(\w+_)?dph", s)):
            return "replay-log"
        if s.startswith(b"timestamp,arbitration_id"):
            return "can-csv"
        if s.startswith(b"#"):
            continue
        return "other"
    return "other"


def open_replay_source(path: str, opts: SourceOptions | None = None) -> Source:
    """A source replaying ``path``: a replay-log CSV, a raw serial capture (protocol from
    ``--protocol`` or its ``.json`` sidecar), a CAN log (.asc .blf .trc .csv .log with
    ``--dbc`` or a sidecar), another tool's recording (fogmon.sources.formats), or an
    archive folder (``open_archive``). Not paced: the
    pipeline paces (``--realtime``)."""
    opts = SourceOptions() if opts is None else opts
    from fogmon.capture import read_sidecar
    from fogmon.sources.formats import open_reader
    from fogmon.sources.replay import ReplayLogSource, open_raw_capture
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FogmonError(f"{path}: no such file")
    other = open_reader(path, opts)  # ROS bag/MCAP, PX4 ULog, MDF4, LAS (fogmon.sources.formats)
    if other is not None:
        return other
    if os.path.isdir(path):
        return open_archive(path, opts)
    if os.path.splitext(path)[1].lower() == ".toml":  # a sensor model: stream its simulation (endless)
        from fogmon.sources.simulated import SimulatedSource
        return SimulatedSource(path)
    if os.path.splitext(path)[1].lower() == ".parquet":  # a Parquet replay log (fogmon.parquet_log)
        from fogmon.sources.parquet import ParquetLogSource
        return ParquetLogSource(path, tolerate=opts.tolerate_bad_rows,
                                max_abs_dph=opts.max_rate_dph or pl.GENERIC_MAX_ABS_DPH, axis=opts.axis)
    side = read_sidecar(path)
    ext = os.path.splitext(path)[1].lower()
    kind = _sniff(path) if not side else side.get("kind")
    if kind == "can" or ext in CAN_LOG_SUFFIXES or kind == "can-csv":
        from fogmon.sources.can_source import open_can_log
        return open_can_log(path, opts.dbc, opts.can_options(), side)
    if kind == "serial" or (opts.protocol and kind != "replay-log"):
        return open_raw_capture(path, opts.codec_options())
    if kind == "replay-log" or ext == ".csv":
        return ReplayLogSource(path, tolerate=opts.tolerate_bad_rows,
                               max_abs_dph=opts.max_rate_dph or pl.GENERIC_MAX_ABS_DPH, axis=opts.axis)
    raise FogmonError(f"{path}: not a replay log; for a raw serial capture give --protocol "
                      f"({', '.join(PROTOCOLS)}), for a CAN log use .asc/.blf/.trc/.csv/.log with --dbc")


def _log_axes(path: str) -> tuple[str, ...]:
    """The axes of a replay-log piece (CSV or Parquet), from its header."""
    if path.endswith(".parquet"):
        from fogmon.parquet_log import ParquetRows
        return ParquetRows(path).axes
    from fogmon.recording import ReplayLogReader
    return ReplayLogReader(path).axes


def open_archive(directory: str, opts: SourceOptions) -> Source:
    """An archive folder (fogmon monitor --archive) as one recording: its replay-log pieces
    samples-NNNN.csv in order; or, when the folder has none or the command line gives
    decoder options (--protocol, --kvh-*, --axis, --columns, --rate-hz, --dbc, --can-*)
    to decode it again, its raw capture pieces (raw-NNNN.bin or frames-NNNN.asc) as one
    stream. One piece alone is replayed by naming its file. ``--max-rate-dph`` gates
    whichever is replayed and does not by itself ask for decoding again, nor does
    ``--axis`` when the pieces are multi-axis logs (it then picks their axes)."""
    from fogmon.capture import read_sidecar
    from fogmon.pieces import find_pieces, piece_path
    from fogmon.sinks.archive import CAN_CAPTURE, REPLAY_LOG, SERIAL_CAPTURE
    from fogmon.sinks.parquet_pieces import piece_files
    from fogmon.sources.replay import ReplayLogSet, ReplayLogSource, open_raw_capture

    logs = find_pieces(directory, REPLAY_LOG) or piece_files(directory)
    serial, frames = find_pieces(directory, SERIAL_CAPTURE), find_pieces(directory, CAN_CAPTURE)
    decode = opts.asks_decoding(axis=not (opts.axis and logs and _log_axes(logs[0])))
    if serial and (decode or not logs):
        return open_raw_capture(serial, opts.codec_options())
    if frames and (decode or not logs):
        from fogmon.sources.can_source import open_can_log
        sides = [read_sidecar(p) or {} for p in frames]
        fields = (
            "message",
            "rate_signal",
            "rate_unit",
            "temp_signal",
            "counter_signal",
            "valid_signal",
            "sample_rate_hz",
            "max_rate_dph",
            "dbc",
        )
        for p, side in zip(frames[1:], sides[1:], strict=True):
            if any(side.get(k) != sides[0].get(k) for k in fields):
                raise FogmonError(f"{p}: its sidecar's decoder options or DBC differ from {frames[0]}'s: "
                                  f"not pieces of one CAN log")
        return open_can_log(frames, opts.dbc, opts.can_options(), sides[0])
    tolerate = opts.tolerate_bad_rows
    max_abs_dph = opts.max_rate_dph or pl.GENERIC_MAX_ABS_DPH
    if logs and logs[0].endswith(".parquet"):  # Parquet pieces (and parts of a piece never joined): one recording
        from fogmon.sources.parquet import ParquetLogSource
        return ParquetLogSource(logs, tolerate=tolerate, max_abs_dph=max_abs_dph, axis=opts.axis)
    if len(logs) == 1:
        return ReplayLogSource(logs[0], tolerate=tolerate, max_abs_dph=max_abs_dph, axis=opts.axis)
    if logs:
        return ReplayLogSet(logs, tolerate=tolerate, max_abs_dph=max_abs_dph, axis=opts.axis)
    raise FogmonError(f"{directory}: is a folder without an archive (no pieces of {REPLAY_LOG}, samples.parquet, "
                      f"{SERIAL_CAPTURE} or {CAN_CAPTURE} such as {piece_path(REPLAY_LOG, 1)}); give a replay log, "
                      f"raw capture or CAN log")
