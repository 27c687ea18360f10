"""The archive: while monitoring, everything a live source delivers goes to disk, so
nothing is lost.

Under one directory, in pieces of ``rotate_s`` s of recording time (fogmon.formats.archive:
piece k holds recording time [(k-1) S, k S) from the first sample; numbered from 0001):

- ``samples-NNNN.csv``: the decoded samples as a replay log (docs/formats.md), each
  piece complete with magic line, metadata (``piece: N``) and header. Valid samples only
  (a replay log holds no NaN); lost and invalid samples show as time gaps, which every
  reader turns back into invalid placeholders. A multi-axis stream (``block.axes``)
  writes one ``rate_<axis>_dph`` column per axis, and a row only where every axis is
  valid: a sample with only some axes valid is left out and counted
  (``partial_samples_dropped``); the raw capture keeps it, and ``fogmon replay`` of the
  capture decodes it with every axis as the device sent it. With ``samples_format="parquet"``
  (``archive_format`` parquet) ``samples-NNNN.parquet`` instead, written in row groups
  (fogmon.sinks.parquet_pieces: a SIGKILL loses at most the row group being filled).
- the raw input as a capture ``fogmon replay`` decodes to the same samples: for a
  serial gyro ``raw-NNNN.bin`` (the bytes exactly as received) plus ``raw-NNNN.bin.json``
  (protocol, decoder options, outages as byte offsets in that piece); for a CAN gyro
  ``frames-NNNN.asc`` (python-can ASC log of every frame received) plus
  ``frames-NNNN.asc.json`` and one copy of the DBC. A raw piece begins at a frame
  boundary (where the decoder holds no partial frame) a little after the samples piece
  of the same number (by the input read but not yet processed when the pipeline reached
  the seam): concatenated, the raw pieces are exactly the byte stream received.

Files are created with their first data (a run that received nothing leaves no file,
and no folder it created) and written in whole lines/chunks straight to the OS at least
every ``flush_s`` (default 0.5 s, by a background thread even when no data flows), so a
SIGKILL loses at most the last ``flush_s`` of data and never leaves a half-written CSV
row. The raw taps may be called from another thread than the pipeline's (the source's
decoding thread, right after it decoded those bytes): the raw capture keeps being written
even while the pipeline is slow, and holds exactly the input the source decoded and
counted (a run of ``duration_s`` ends it with the run's last frame).
"""
from __future__ import annotations

import contextlib
import io
import os
import shutil
import threading
import time
from datetime import UTC, datetime
from typing import Any

import numpy as np

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.formats.archive import CAN_CAPTURE, REPLAY_LOG, SERIAL_CAPTURE, find_pieces, piece_files, piece_path
from fogmon.formats.capture import new_sidecar, write_sidecar
from fogmon.formats.replay_log import append_replay_rows, write_replay_header
from fogmon.sinks.base import Sink, Summary
from fogmon.sinks.parquet_pieces import ROW_GROUP_S, ParquetPieces
from fogmon.sources.base import CaptureSource, Source


def replay_rows(block: Block) -> tuple[np.ndarray, int, int]:
    """Which samples of ``block`` a replay log holds (it has no NaN): those valid on every
    axis with every aux channel finite. Returns that mask, the samples left out for having
    only some axes valid, and those left out (valid on every axis) for a non-finite aux."""
    valid: np.ndarray = np.all(block.valid, axis=1) if block.axes else block.valid
    partial = int(np.count_nonzero(np.any(block.valid, axis=1) & ~valid)) if block.axes else 0
    keep = valid.copy()
    for a in block.aux.values():
        keep &= np.isfinite(a)
    return keep, partial, int(valid.sum() - keep.sum())


class _KeepOpen(io.StringIO):
    """A StringIO that python-can's writer cannot close (we move its text to disk)."""

    def close(self) -> None:
        pass


class Archive(Sink):
    """Archive of ``source`` under ``directory`` (created if needed; must not hold an
    archive yet). A pipeline sink (``run_pipeline(source, config, [..., archive])``):
    ``block`` (= ``write``) takes the decoded blocks, ``rotate`` starts the next piece,
    ``finish`` closes; the source feeds the raw capture through the tap methods
    ``raw(bytes)``, ``frame(can.Message)``, ``outage(elapsed_s, missing_est)`` and ``placed``
    (registered here with ``source.add_tap``). ``replay_log_path`` and ``capture_path``
    name the current piece's files. Counters: ``rows_written``, ``rows_without_aux``
    (valid samples whose aux channel was not yet known, e.g. KVH format C before its
    first temperature frame; not written), ``partial_samples_dropped`` (a multi-axis
    stream only: samples with some but not all axes valid; not written), ``raw_bytes``,
    ``raw_frames``. A multi-axis source (its ``axes``) needs ``samples_format="csv"``."""

    def __init__(self, directory: str, source: Source, flush_s: float = 0.5, clock=time.monotonic,
                 background_flush: bool = True, samples_format: str = "csv",
                 row_group_s: float = ROW_GROUP_S) -> None:
        self.directory = os.fspath(directory)
        self._created_dir = not os.path.isdir(self.directory)
        try:
            os.makedirs(self.directory, exist_ok=True)
        except OSError as e:
            raise FogmonError(f"`archive` {self.directory}: cannot create: {e.strerror}") from None
        held = [p for name in (REPLAY_LOG, SERIAL_CAPTURE, CAN_CAPTURE) for p in find_pieces(self.directory, name)]
        held += piece_files(self.directory)
        if held:
            raise FogmonError(f"`archive` {self.directory}: already holds an archive ({os.path.basename(held[0])}); "
                              f"give a new folder")
        if not os.access(self.directory, os.W_OK):
            raise FogmonError(f"`archive` {self.directory}: cannot write there")
        self.source = source
        self.flush_s = float(flush_s)
        self._clock = clock
        self._lock = threading.RLock()
        self._last_flush = clock()
        self.started_utc = datetime.now(UTC).isoformat(timespec="seconds")
        self.counters = {"rows_written": 0, "rows_without_aux": 0, "raw_bytes": 0, "raw_frames": 0}
        if source.axes:
            self.counters["partial_samples_dropped"] = 0
        self.piece = 1
        self._pieces: set[int] = set()          # pieces that have a file
        self._done = False
        self._csv_fd: int | None = None
        self._csv_buf = io.StringIO()
        self._aux_names: list[str] | None = None
        self._axes: tuple[str, ...] = ()
        self.replay_log_path = os.path.join(self.directory, piece_path(REPLAY_LOG, 1))
        self._parquet = ParquetPieces(self.directory, source.sample_rate_hz, row_group_s) \
            if samples_format == "parquet" else None
        self._capture_source = source if isinstance(source, CaptureSource) else None
        base = dict(self._capture_source.capture_spec()) if self._capture_source is not None else None
        self._dbc = base.pop("dbc_path", None) if base else None
        self._spec_base = base
        self._spec: dict[str, Any] = {}          # the current capture piece's sidecar
        self._cap_fd: int | None = None
        self._cap_buf = bytearray()
        self._cap_written = 0                    # bytes of the current capture piece on disk
        self._cut_pending = False                # start a new capture piece at the next frame boundary
        self._can_writer: Any = None             # a can.ASCWriter into _can_text while a CAN piece is open
        self._can_text = _KeepOpen()
        self._capture_name = SERIAL_CAPTURE
        self.capture_path: str | None = None
        if self._capture_source is not None and base is not None:
            self._capture_name = SERIAL_CAPTURE if base.get("kind") == "serial" else CAN_CAPTURE
            self.capture_path = os.path.join(self.directory, piece_path(self._capture_name, 1))
            self._capture_source.add_tap(self)
        self._closed = threading.Event()
        if background_flush:
            threading.Thread(target=self._flusher, name="fogmon-archive-flush", daemon=True).start()

    def _flusher(self) -> None:
        while not self._closed.wait(self.flush_s):
            self.flush()

    # -- decoded samples -------------------------------------------------------------
    def write(self, block: Block) -> None:
        """Append the valid samples of ``block`` to the replay log."""
        with self._lock:
            self._write(block)

    def _write(self, block: Block) -> None:
        if self._aux_names is None and len(block):
            self._aux_names, self._axes = list(block.aux), block.axes
        aux_names = self._aux_names or []
        if len(block) and not self._done:
            keep, partial, without_aux = replay_rows(block)
            self.counters["rows_without_aux"] += without_aux
            if block.axes:
                self.counters["partial_samples_dropped"] = self.counters.get("partial_samples_dropped", 0) + partial
            if keep.any() and self._parquet is not None:
                self._pieces.add(self.piece)
                self._parquet.write(self.piece, aux_names, self._meta(), block.t_s[keep], block.rate_dph[keep],
                                    {k: block.aux[k][keep] for k in aux_names}, block.axes)
                self.counters["rows_written"] += int(keep.sum())
            elif keep.any():
                if self._csv_fd is None:
                    self._open_replay_log(aux_names)
                append_replay_rows(self._csv_buf, block.t_s[keep], block.rate_dph[keep],
                                   {k: block.aux[k][keep] for k in aux_names})
                self.counters["rows_written"] += int(keep.sum())
        self._maybe_flush()

    def _open_replay_log(self, aux_names: list[str]) -> None:
        self.replay_log_path = os.path.join(self.directory, piece_path(REPLAY_LOG, self.piece))
        self._csv_fd = os.open(self.replay_log_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self._pieces.add(self.piece)
        write_replay_header(self._csv_buf, aux_names, self._meta(), self._axes)

    def _meta(self) -> dict:
        """The replay-log metadata of the current piece."""
        return {"sample_rate_hz": f"{self.source.sample_rate_hz:.12g}", "sensor": self.source.name,
                "started_utc": self.started_utc, "piece": self.piece}

    def _close_replay_log(self) -> None:
        self._flush()
        if self._parquet is not None:
            self._parquet.end_piece()
        if self._csv_fd is not None:
            os.close(self._csv_fd)
            self._csv_fd = None

    def block(self, block: Block) -> None:
        self.write(block)

    def rotate(self, piece: int, t_s: float) -> None:
        """Piece ``piece`` begins: the replay log goes on in a new file now, the raw
        capture at its next frame boundary."""
        with self._lock:
            self._close_replay_log()
            self.piece = piece
            self._cut_pending = self._cap_fd is not None

    def finish(self, summary: Summary) -> None:
        self.close()
        if self._pieces:
            n = len(self._pieces)
            partial = self.counters.get("partial_samples_dropped", 0)
            summary.outputs.append(f"archive {self.directory} ({self.counters['rows_written']} samples"
                                   + (f" in {n} pieces" if n > 1 else "")
                                   + (f"; {partial} with only some axes valid left out of the replay log, kept in "
                                      f"the raw capture" if partial else "") + ")")

    # -- raw capture taps (called by the source) --------------------------------------
    def raw(self, data: bytes) -> None:
        with self._lock:
            self._append_raw(data)
            self.counters["raw_bytes"] += len(data)
            self._maybe_flush()

    def frame(self, msg) -> None:
        with self._lock:
            self._append_frame(msg)
            self.counters["raw_frames"] += 1
            self._maybe_flush()

    def outage(self, elapsed_s: float, missing_est: float) -> None:
        """The source's port was closed and reopened: ``elapsed_s`` s since its last input,
        about ``missing_est`` samples lost; recorded in the sidecar (``breaks``) at the
        current byte offset of the serial capture piece, so a replay places the same gap
        (a CAN log carries its own timestamps)."""
        with self._lock:
            if self._spec_base is not None and self._spec_base.get("kind") == "serial" and self._open_capture():
                self._spec["breaks"].append({"offset": self._cap_offset(), "missing_est": float(missing_est),
                                             "elapsed_s": float(elapsed_s)})
                self._write_sidecar()
            self.flush()

    def placed(self, frame: int, missing: int, rule: int, wraps: int = 0) -> None:
        """The source's grid placed ``missing`` samples before the ``frame``-th frame decoded
        from the next bytes by its clock (``rule``: an index of fogmon.sources.grid.WHY;
        ``wraps`` of them whole counter wraps), which the bytes alone would not give again;
        recorded in the sidecar (``breaks``) at the current byte offset so a replay places
        the same (``missing_est`` too, for readers that know only outages)."""
        with self._lock:
            if self._spec_base is not None and self._spec_base.get("kind") == "serial" and self._open_capture():
                self._spec["breaks"].append({"offset": self._cap_offset(), "missing_est": float(missing),
                                             "frame": int(frame), "missing": int(missing), "rule": int(rule),
                                             "wraps": int(wraps)})
                self._write_sidecar()

    # -- capture pieces --------------------------------------------------------------------
    def _append_raw(self, data: bytes) -> None:
        """Serial bytes into the capture; a pending cut happens where the decoder, which
        has just been fed ``data``, holds no partial frame (else at a later call)."""
        pending = self._capture_source.pending if self._capture_source is not None else 0
        at = len(data) - pending if self._cut_pending else -1
        if at >= 0:                              # (< 0: the frame under way began in an earlier chunk)
            if at and self._open_capture():
                self._cap_buf += data[:at]
            self._close_capture()
            data = data[at:]
        if data and self._open_capture():
            self._cap_buf += data

    def _append_frame(self, msg) -> None:
        if self._cut_pending:
            self._close_capture()
        if self._open_capture():
            self._can_writer.on_message_received(msg)

    def _open_capture(self) -> bool:
        """Make sure the current capture piece is open (False once the archive is closed)."""
        if self._done or self._spec_base is None:   # closed, or a source without a raw capture
            return False
        if self._cap_fd is not None:
            return True
        self.capture_path = os.path.join(self.directory, piece_path(self._capture_name, self.piece))
        self._cap_fd = os.open(self.capture_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self._cap_written = 0
        self._pieces.add(self.piece)
        self._spec = new_sidecar(self._spec_base, self.started_utc, self.piece)
        if self._spec_base["kind"] == "can":
            import can
            self._can_text = _KeepOpen()
            self._can_writer = can.ASCWriter(self._can_text)
            if self._dbc:
                name = os.path.basename(self._dbc)
                if not os.path.exists(os.path.join(self.directory, name)):
                    shutil.copyfile(self._dbc, os.path.join(self.directory, name))
                self._spec["dbc"] = name
        self._write_sidecar()
        return True

    def _close_capture(self) -> None:
        self._cut_pending = False
        if self._cap_fd is None:
            return
        if self._can_writer is not None:
            self._can_writer.stop()              # writes the ASC end line into our buffer
        self._flush()
        os.close(self._cap_fd)
        self._cap_fd = self._can_writer = None

    def _cap_offset(self) -> int:
        """Bytes in the current serial capture piece so far."""
        return self._cap_written + len(self._cap_buf)

    # -- disk ----------------------------------------------------------------------------
    def _write_sidecar(self) -> None:
        if self.capture_path is not None:
            write_sidecar(self.capture_path, self._spec)

    def _maybe_flush(self) -> None:
        if self._clock() - self._last_flush >= self.flush_s:
            self._flush()

    def flush(self) -> None:
        """Hand everything buffered to the OS (survives a SIGKILL of this process)."""
        with self._lock:
            self._flush()

    def _flush(self) -> None:
        self._last_flush = self._clock()
        if self._csv_fd is not None:
            text = self._csv_buf.getvalue()
            if text:
                _write_all(self._csv_fd, text.encode("utf-8"))
                self._csv_buf = io.StringIO()
        if self._cap_fd is None:
            return
        if self._can_writer is not None:
            t = self._can_text.getvalue()
            if t:
                _write_all(self._cap_fd, t.encode("ascii"))
                self._can_text.seek(0)
                self._can_text.truncate()
        elif self._cap_buf:
            _write_all(self._cap_fd, bytes(self._cap_buf))
            self._cap_written += len(self._cap_buf)
            self._cap_buf.clear()

    def close(self) -> None:
        """Flush and close the files (idempotent); taps called later are ignored. A
        folder this archive created and left empty is removed."""
        self._closed.set()
        with self._lock:
            if self._done:
                return
            self._close_replay_log()
            self._close_capture()
            self._done = True
        if self._created_dir and not self._pieces:
            with contextlib.suppress(OSError):
                os.rmdir(self.directory)

    def __enter__(self) -> Archive:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]
