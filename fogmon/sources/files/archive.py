"""An archive folder (``fogmon monitor --archive``; layout: fogmon.formats.archive)
replayed as one recording: its replay-log pieces, or its raw capture pieces decoded
again."""
from __future__ import annotations

from fogmon.errors import FogmonError
from fogmon.formats.archive import CAN_CAPTURE, PARQUET_LOG, REPLAY_LOG, SERIAL_CAPTURE, archive_files, piece_path
from fogmon.formats.capture import CAN_DECODER_FIELDS
from fogmon.formats.parquet_log import ParquetRows
from fogmon.formats.replay_log import ReplayLogReader
from fogmon.sources.base import Source
from fogmon.sources.files.capture import open_raw_capture, read_capture_sidecar
from fogmon.sources.files.parquet import ParquetLogSource
from fogmon.sources.files.replay_log import ReplayLogSet, ReplayLogSource
from fogmon.sources.options import SourceOptions


def _log_axes(path: str) -> tuple[str, ...]:
    """The axes of a replay-log piece (CSV or Parquet), from its header."""
    return ParquetRows(path).axes if path.endswith(".parquet") else ReplayLogReader(path).axes


def open_source(directory: str, opts: SourceOptions) -> Source:
    """An archive folder (fogmon monitor --archive) as one recording: its replay-log pieces
    samples-NNNN.csv in order; or, when the folder has none or ``opts`` gives decoder
    options (``SourceOptions.asks_decoding``: ``protocol``, ``kvh_*``, ``axis``, ``columns``,
    ``sample_rate_hz``, ``dbc``, ``can_*``) to decode it again, its raw capture pieces
    (raw-NNNN.bin or frames-NNNN.asc) as one stream. One piece alone is replayed by naming
    its file. ``max_rate_dph`` gates whichever is replayed and does not by itself ask for
    decoding again, nor does ``axis`` when the pieces are multi-axis logs (it then picks their axes)."""
    held = archive_files(directory)
    logs, serial, frames = held.logs, held.serial, held.frames
    decode = opts.asks_decoding(axis=not (opts.axis and logs and _log_axes(logs[0])))
    if serial and (decode or not logs):
        return open_raw_capture(serial, opts.codec_options())
    if frames and (decode or not logs):
        from fogmon.sources.files.can_log import open_can_log
        sides = [read_capture_sidecar(p) or {} for p in frames]
        fields = (*CAN_DECODER_FIELDS, "dbc")
        for p, side in zip(frames[1:], sides[1:], strict=True):
            if any(side.get(k) != sides[0].get(k) for k in fields):
                raise FogmonError(f"{p}: its sidecar's decoder options or DBC differ from {frames[0]}'s: "
                                  f"not pieces of one CAN log")
        return open_can_log(frames, opts.dbc, opts.can_options(), sides[0], opts.force_rate, opts.resample_hz)
    tolerate, max_abs_dph = opts.tolerate_bad_rows, opts.file_gate_dph
    if logs and logs[0].endswith(".parquet"):  # Parquet pieces (and parts of a piece never joined): one recording
        return ParquetLogSource(logs, tolerate=tolerate, max_abs_dph=max_abs_dph, axis=opts.axis)
    if len(logs) == 1:
        return ReplayLogSource(logs[0], tolerate=tolerate, max_abs_dph=max_abs_dph, axis=opts.axis)
    if logs:
        return ReplayLogSet(logs, tolerate=tolerate, max_abs_dph=max_abs_dph, axis=opts.axis)
    raise FogmonError(f"{directory}: is a folder without an archive (no pieces of {REPLAY_LOG}, {PARQUET_LOG}, "
                      f"{SERIAL_CAPTURE} or {CAN_CAPTURE} such as {piece_path(REPLAY_LOG, 1)}); give a replay log, "
                      f"raw capture or CAN log")
