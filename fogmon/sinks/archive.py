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

One archive, one writer: the folder is locked (``flock`` of its lock file, which holds
the writer's pid) before anything else, so a second writer gets a one-line error; a
lock left by a process that died is free again (the kernel releases it).

A write that fails (a full disk, a quota, an I/O error, a file-size limit) stops the
archive, never with a traceback from the flush thread: every file it wrote ends on a
whole row (a replay-log piece is cut back to its last whole row, a capture to its last
flush; a piece left without data is removed; a Parquet piece keeps the parts written),
so the archive replays; ``error`` is the one-line FogmonError naming the file and the
free space, and the next ``block`` raises StopRun so that the run ends cleanly with its
summary. Once ``SPACE_CHECK_S`` s of samples are on disk, the bytes per sample are
measured (``bytes_per_sample``: samples and raw capture together) and a FogmonWarning
says when the free space will not last the run (``duration_s``, else ``SPACE_WARN_S``).
"""
from __future__ import annotations

import contextlib
import fcntl
import io
import os
import shutil
import socket
import threading
import time
import warnings
from datetime import UTC, datetime
from typing import Any

import numpy as np

from fogmon.block import Block
from fogmon.errors import FogmonError, FogmonWarning
from fogmon.formats.archive import (
    CAN_CAPTURE,
    LOCK,
    REPLAY_LOG,
    SERIAL_CAPTURE,
    find_pieces,
    piece_files,
    piece_path,
)
from fogmon.formats.capture import SIDECAR_SUFFIX, new_sidecar, write_sidecar
from fogmon.formats.replay_log import append_replay_rows, write_replay_header
from fogmon.outputs import free_bytes, write_failed
from fogmon.sinks.base import Sink, StopRun, Summary
from fogmon.sinks.parquet_pieces import ROW_GROUP_S, ParquetPieces
from fogmon.sources.base import CaptureSource, Source

#: recording time (s) on disk after which the bytes per sample are measured and the free
#: space checked against the rest of the run
SPACE_CHECK_S = 60.0
#: without a run duration, warn when the free space lasts less than this (s): a day
SPACE_WARN_S = 86400.0


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
                 row_group_s: float = ROW_GROUP_S, duration_s: float | None = None) -> None:
        self.directory = os.fspath(directory)
        self._created_dir = False
        if not os.path.isdir(self.directory):
            try:
                os.mkdir(self.directory)     # in an existing folder: none above it is made
                self._created_dir = True
            except FileExistsError:
                pass                         # made just now by another writer: the lock decides
            except OSError as e:
                raise FogmonError(f"`archive` {self.directory}: cannot create: {e.strerror}") from None
        self._lock_fd: int | None = None
        self._take_lock()
        try:
            held = [p for name in (REPLAY_LOG, SERIAL_CAPTURE, CAN_CAPTURE) for p in find_pieces(self.directory, name)]
            held += piece_files(self.directory)
            if held:
                raise FogmonError(f"`archive` {self.directory}: already holds an archive "
                                  f"({os.path.basename(held[0])}); give a new folder")
        except BaseException:
            self._release_lock()
            raise
        self.error: FogmonError | None = None    # the write that failed: the archive stopped there
        self._stop_sent = False
        self.duration_s = duration_s
        self.bytes_per_sample: float | None = None   # measured once SPACE_CHECK_S s are on disk
        self._bytes_written = 0                  # bytes of samples and capture on disk
        self._rows_on_disk = 0
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
        self._csv_rows = 0                       # rows in _csv_buf
        self._csv_size = 0                       # bytes of the current replay-log piece on disk
        self._csv_header = 0                     # of which its header
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
            self.flush()          # a failed write is noted (self.error), never raised here

    # -- lock --------------------------------------------------------------------------
    def _take_lock(self) -> None:
        """Take the folder's lock (non-blocking) or raise a FogmonError naming its holder."""
        path = os.path.join(self.directory, LOCK)
        while True:
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as e:
                raise FogmonError(f"`archive` {self.directory}: cannot write there: {e.strerror}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.read(fd, 200).decode("utf-8", "replace").strip() or "?"
                os.close(fd)
                raise FogmonError(f"`archive` {self.directory}: another fogmon (pid {holder}) is writing an archive "
                                  f"there; give another folder") from None
            try:   # the holder may have removed the file as it finished: lock the one in the folder
                same = os.path.samestat(os.fstat(fd), os.stat(path))
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} on {socket.gethostname()}\n".encode())
        self._lock_fd = fd

    def _release_lock(self) -> None:
        if self._lock_fd is None:
            return
        with contextlib.suppress(OSError):
            os.remove(os.path.join(self.directory, LOCK))
        os.close(self._lock_fd)
        self._lock_fd = None

    # -- decoded samples -------------------------------------------------------------
    def write(self, block: Block) -> None:
        """Append the valid samples of ``block`` to the replay log."""
        with self._lock:
            self._write(block)

    def _write(self, block: Block) -> None:
        if self.error is not None:
            if not self._stop_sent:      # once: the pipeline ends the run, its summary printed
                self._stop_sent = True
                raise StopRun(f"the archive could not write: {self.error.message}")
            return
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
                with self._guard(self._parquet_path):
                    self._parquet.write(self.piece, aux_names, self._meta(), block.t_s[keep], block.rate_dph[keep],
                                        {k: block.aux[k][keep] for k in aux_names}, block.axes)
                self.counters["rows_written"] += int(keep.sum())
            elif keep.any():
                if self._csv_fd is None:
                    with self._guard(lambda: self.replay_log_path):
                        self._open_replay_log(aux_names)
                if self._csv_fd is not None:
                    append_replay_rows(self._csv_buf, block.t_s[keep], block.rate_dph[keep],
                                       {k: block.aux[k][keep] for k in aux_names})
                    self._csv_rows += int(keep.sum())
                    self.counters["rows_written"] += int(keep.sum())
        self._maybe_flush()

    @property
    def rows_on_disk(self) -> int:
        """Rows of decoded samples handed to the OS (whole rows)."""
        return self._rows_on_disk + (self._parquet.rows_on_disk if self._parquet is not None else 0)

    def _parquet_path(self) -> str | None:
        return self._parquet.path if self._parquet is not None else None

    def _open_replay_log(self, aux_names: list[str]) -> None:
        self.replay_log_path = os.path.join(self.directory, piece_path(REPLAY_LOG, self.piece))
        self._csv_fd = os.open(self.replay_log_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self._csv_size = self._csv_rows = 0
        self._pieces.add(self.piece)
        write_replay_header(self._csv_buf, aux_names, self._meta(), self._axes)
        self._csv_header = len(self._csv_buf.getvalue().encode("utf-8"))

    def _meta(self) -> dict:
        """The replay-log metadata of the current piece."""
        return {"sample_rate_hz": f"{self.source.sample_rate_hz:.12g}", "sensor": self.source.name,
                "started_utc": self.started_utc, "piece": self.piece}

    def _close_replay_log(self) -> None:
        self._flush()
        if self._parquet is not None:
            with self._guard(self._parquet_path):
                self._parquet.end_piece(write_held=self.error is None)
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
            rows = self.counters["rows_written"] if self.error is None else self.rows_on_disk
            summary.outputs.append(f"archive {self.directory} ({rows} samples"
                                   + (f" in {n} pieces" if n > 1 else "")
                                   + (f"; {partial} with only some axes valid left out of the replay log, kept in "
                                      f"the raw capture" if partial else "")
                                   + ("; INCOMPLETE: writing stopped at a failed write, every file ends on a whole "
                                      "row" if self.error is not None else "") + ")")

    # -- raw capture taps (called by the source) --------------------------------------
    def raw(self, data: bytes) -> None:
        with self._lock:
            with self._guard(lambda: self.capture_path):
                self._append_raw(data)
            self.counters["raw_bytes"] += len(data)
            self._maybe_flush()

    def frame(self, msg) -> None:
        with self._lock:
            with self._guard(lambda: self.capture_path):
                self._append_frame(msg)
            self.counters["raw_frames"] += 1
            self._maybe_flush()

    def outage(self, elapsed_s: float, missing_est: float) -> None:
        """The source's port was closed and reopened: ``elapsed_s`` s since its last input,
        about ``missing_est`` samples lost; recorded in the sidecar (``breaks``) at the
        current byte offset of the serial capture piece, so a replay places the same gap
        (a CAN log carries its own timestamps)."""
        with self._lock:
            with self._guard(lambda: self.capture_path):
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
        with self._lock, self._guard(lambda: self.capture_path):
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
        """Make sure the current capture piece is open (False once the archive is closed
        or stopped by a failed write)."""
        if self._done or self._spec_base is None or self.error is not None:   # closed, stopped, or no capture
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
        if self._can_writer is not None and self.error is None:
            self._can_writer.stop()              # writes the ASC end line into our buffer
        self._flush()
        if self._cap_fd is not None:             # (a failed write has closed it)
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
        if self.error is not None:
            return
        if self._csv_fd is not None:
            text = self._csv_buf.getvalue()
            if text:
                with self._guard(lambda: self.replay_log_path):
                    data = text.encode("utf-8")
                    try:
                        _write_all(self._csv_fd, data)
                    except OSError as e:   # keep the whole rows that reached the file before it failed
                        self._count_written(data, data.rfind(b"\n", 0, getattr(e, "written", 0)) + 1)
                        raise
                    self._count_written(data, len(data))
                    self._csv_buf, self._csv_rows = io.StringIO(), 0
        if self._cap_fd is not None and self.error is None:
            with self._guard(lambda: self.capture_path):
                if self._can_writer is not None:
                    data = self._can_text.getvalue().encode("ascii")
                    self._can_text.seek(0)
                    self._can_text.truncate()
                else:
                    data = bytes(self._cap_buf)
                    self._cap_buf.clear()
                if data:
                    _write_all(self._cap_fd, data)
                    self._cap_written += len(data)
                    self._bytes_written += len(data)
        if self.bytes_per_sample is None and self.error is None:
            self._check_space()

    def _count_written(self, data: bytes, size: int) -> None:
        """The first ``size`` bytes of the flushed ``data`` (whole lines) are on disk."""
        header = self._csv_header if self._csv_size == 0 else 0   # the first flush begins with the header
        self._csv_size += size
        self._bytes_written += size
        self._rows_on_disk += data.count(b"\n", min(header, size), size)

    # -- failed writes and free space ---------------------------------------------------
    @contextlib.contextmanager
    def _guard(self, path):
        """A failed write in the block (``path()`` names the file) stops the archive
        (``_fail``) instead of raising."""
        try:
            yield
        except (OSError, FogmonError) as e:
            self._fail(path() or self.directory, e)

    def _fail(self, path: str, e: OSError | FogmonError) -> None:
        """Note the first failed write and leave every file on a whole row: the current
        replay log cut back to its last whole row, the capture to its last flush, a
        file left without data removed (with its sidecar); nothing more is written."""
        if self.error is None:
            self.error = e if isinstance(e, FogmonError) else write_failed("`archive`", path, e)
        self._csv_buf, self._csv_rows = io.StringIO(), 0
        self._cap_buf.clear()
        self._can_text.seek(0)
        self._can_text.truncate()
        if self._csv_fd is not None:
            _cut(self._csv_fd, self.replay_log_path, self._csv_size, self._csv_header)
            self._csv_fd = None
        if self._cap_fd is not None and self.capture_path is not None:
            _cut(self._cap_fd, self.capture_path, self._cap_written, 0)
            self._cap_fd = self._can_writer = None

    def _check_space(self) -> None:
        """Once SPACE_CHECK_S s of samples are on disk: measure the bytes per sample and
        warn when the free space will not last the rest of the run."""
        rate = float(self.source.sample_rate_hz)
        rows = self.rows_on_disk
        if rows < SPACE_CHECK_S * rate:
            return
        written = self._bytes_written + (self._parquet.bytes_on_disk if self._parquet is not None else 0)
        self.bytes_per_sample = written / rows
        free = free_bytes(self.directory)
        if free is None:
            return
        lasts_s = free / (self.bytes_per_sample * rate)
        left_s = self.duration_s - rows / rate if self.duration_s else SPACE_WARN_S
        if lasts_s < left_s:
            warnings.warn(f"`archive` {self.directory}: {free / 1e9:.3g} GB free hold {lasts_s / 3600:.3g} h more "
                          f"at the measured {self.bytes_per_sample:.1f} bytes per sample ({rate:g} Hz), less than "
                          f"the {left_s / 3600:.3g} h {'left of the run' if self.duration_s else 'of a day'}; the "
                          f"run stops cleanly when the disk is full", FogmonWarning, stacklevel=2)

    def close(self) -> None:
        """Flush and close the files (idempotent); taps called later are ignored. A
        folder this archive created and left empty is removed; the lock is released."""
        self._closed.set()
        with self._lock:
            if self._done:
                return
            self._close_replay_log()
            self._close_capture()
            self._done = True
        self._release_lock()
        if self._created_dir:             # left empty (nothing arrived, or nothing could be written)
            with contextlib.suppress(OSError):
                os.rmdir(self.directory)

    def __enter__(self) -> Archive:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _write_all(fd: int, data: bytes) -> None:
    """Write all of ``data``; an OSError carries ``written``, the bytes that reached the
    file before it (a file-size limit or a full disk takes a partial write first)."""
    view = memoryview(data)
    done = 0
    while view:
        try:
            n = os.write(fd, view)
        except OSError as e:
            e.written = done  # type: ignore[attr-defined]
            raise
        done += n
        view = view[n:]


def _cut(fd: int, path: str, size: int, empty: int) -> None:
    """Cut file ``path`` (open as ``fd``) back to ``size`` bytes and close it; removed
    (with a capture's sidecar) when that leaves no more than ``empty`` bytes (no data)."""
    with contextlib.suppress(OSError):
        os.ftruncate(fd, size)
    with contextlib.suppress(OSError):
        os.close(fd)
    if size <= empty:
        for p in (path, path + SIDECAR_SUFFIX):
            with contextlib.suppress(OSError):
                os.remove(p)
