"""The archive: while monitoring, everything a live source delivers goes to disk, so
nothing is lost.

Under one directory:

- ``samples.csv``: the decoded samples as a replay log (CONTRACT section 1). Valid
  samples only (a replay log holds no NaN); lost and invalid samples show as time gaps,
  which every reader turns back into invalid placeholders.
- the raw input as a capture ``fogmon replay`` decodes to the same samples: for a
  serial gyro ``raw.bin`` (the bytes exactly as received) plus ``raw.bin.json`` (protocol,
  decoder options, outages as byte offsets); for a CAN gyro ``frames.asc`` (python-can
  ASC log of every frame received) plus ``frames.asc.json`` and a copy of the DBC.

Files are written in whole lines/chunks straight to the OS at least every ``flush_s``
(default 0.5 s, by a background thread even when no data flows), so a SIGKILL loses at
most the last ``flush_s`` of data and never leaves a half-written CSV row. The raw taps may be called from the source's reader
thread: the raw capture keeps being written even while the consumer is slow.
"""
from __future__ import annotations

import io
import json
import os
import shutil
import threading
import time
from datetime import datetime, timezone

import numpy as np

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.pipeline import Sink
from fogmon.recording import append_replay_rows, write_replay_header
from fogmon.sources.replay import CAPTURE_FORMAT, SIDECAR_SUFFIX

REPLAY_LOG = "samples.csv"
SERIAL_CAPTURE = "raw.bin"
CAN_CAPTURE = "frames.asc"


def default_archive_dir(base: str = ".") -> str:
    """A new time-stamped folder name under ``base``: ``fogmon-archive-YYYYmmddTHHMMSSZ``."""
    return os.path.join(base, datetime.now(timezone.utc).strftime("fogmon-archive-%Y%m%dT%H%M%SZ"))


class _KeepOpen(io.StringIO):
    """A StringIO that python-can's writer cannot close (we move its text to disk)."""

    def close(self) -> None:
        pass


class Archive(Sink):
    """Archive of ``source`` under ``directory`` (created; must not hold an archive yet).
    A pipeline sink (``run_pipeline(source, args, extra_sinks=[archive])``): ``block``
    (= ``write``) takes the decoded blocks, ``finish`` closes; the source feeds the raw capture through
    the tap methods ``raw(bytes)``, ``frame(can.Message)`` and ``outage(elapsed_s, missing_est)``
    (registered with ``source.add_tap(archive)``). Counters: ``rows_written``,
    ``rows_without_aux`` (valid samples whose aux channel was not yet known, e.g. KVH
    format C before its first temperature frame; not written), ``raw_bytes``,
    ``raw_frames``."""

    def __init__(self, directory: str, source, flush_s: float = 0.5, clock=time.monotonic,
                 background_flush: bool = True) -> None:
        self.directory = os.fspath(directory)
        try:
            os.makedirs(self.directory, exist_ok=True)
        except OSError as e:
            raise FogmonError(f"--archive {self.directory}: cannot create: {e.strerror}") from None
        self.replay_log_path = os.path.join(self.directory, REPLAY_LOG)
        if os.path.exists(self.replay_log_path):
            raise FogmonError(f"--archive {self.directory}: already holds an archive ({REPLAY_LOG}); "
                              f"give a new folder")
        self.source = source
        self.flush_s = float(flush_s)
        self._clock = clock
        self._lock = threading.RLock()
        self._last_flush = clock()
        self.started_utc = datetime.now(timezone.utc).isoformat(timespec="seconds")
        self.counters = {"rows_written": 0, "rows_without_aux": 0, "raw_bytes": 0, "raw_frames": 0}
        self._csv_fd = os.open(self.replay_log_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self._csv_buf = io.StringIO()
        self._aux_names: list[str] | None = None
        spec = dict(source.capture_spec()) if hasattr(source, "capture_spec") else None
        self._spec = spec
        self._cap_fd = None
        self._can_writer = None
        self.capture_path = None
        if spec is not None:
            kind = spec.get("kind")
            self.capture_path = os.path.join(self.directory, SERIAL_CAPTURE if kind == "serial" else CAN_CAPTURE)
            self._cap_fd = os.open(self.capture_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            self._cap_buf = bytearray()
            if kind == "can":
                import can
                self._can_text = _KeepOpen()
                self._can_writer = can.ASCWriter(self._can_text)
                dbc = spec.pop("dbc_path", None)
                if dbc:
                    shutil.copyfile(dbc, os.path.join(self.directory, os.path.basename(dbc)))
                    spec["dbc"] = os.path.basename(dbc)
            spec.update({"format": CAPTURE_FORMAT, "started_utc": self.started_utc, "breaks": []})
            self._write_sidecar()
            if hasattr(source, "add_tap"):
                source.add_tap(self)
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
            self._aux_names = list(block.aux)
            meta = {"sample_rate_hz": f"{self.source.rate_hz:.12g}", "sensor": self.source.name,
                    "started_utc": self.started_utc}
            write_replay_header(self._csv_buf, self._aux_names, meta)
        if len(block):
            keep = block.valid.copy()
            for k in self._aux_names:
                keep &= np.isfinite(block.aux[k])
            self.counters["rows_without_aux"] += int(block.valid.sum() - keep.sum())
            append_replay_rows(self._csv_buf, block.t_s[keep], block.rate_dph[keep],
                               {k: block.aux[k][keep] for k in self._aux_names})
            self.counters["rows_written"] += int(keep.sum())
        self._maybe_flush()

    def block(self, block: Block) -> None:
        self.write(block)

    def finish(self, summary) -> None:
        self.close()
        outputs = getattr(summary, "outputs", None)
        if outputs is not None:
            outputs.append(f"archive {self.directory} ({self.counters['rows_written']} samples)")

    # -- raw capture taps (called by the source) --------------------------------------
    def raw(self, data: bytes) -> None:
        with self._lock:
            self._cap_buf += data
            self.counters["raw_bytes"] += len(data)
            self._maybe_flush()

    def frame(self, msg) -> None:
        with self._lock:
            self._can_writer.on_message_received(msg)
            self.counters["raw_frames"] += 1
            self._maybe_flush()

    def outage(self, elapsed_s: float, missing_est: float) -> None:
        """The source heard nothing for ``elapsed_s`` s, about ``missing_est`` samples
        lost; recorded in the sidecar at the current byte offset of the serial capture
        (a CAN log carries its own timestamps)."""
        with self._lock:
            if self._spec is not None and self._spec.get("kind") == "serial":
                self._spec["breaks"].append({"offset": self.counters["raw_bytes"], "missing_est": float(missing_est),
                                             "elapsed_s": float(elapsed_s)})
                self._write_sidecar()
            self.flush()

    # -- disk ----------------------------------------------------------------------------
    def _write_sidecar(self) -> None:
        path = self.capture_path + SIDECAR_SUFFIX
        tmp = path + ".tmp"
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(self._spec, fh, indent=1)
            fh.write("\n")
        os.replace(tmp, path)

    def _maybe_flush(self) -> None:
        if self._clock() - self._last_flush >= self.flush_s:
            self._flush()

    def flush(self) -> None:
        """Hand everything buffered to the OS (survives a SIGKILL of this process)."""
        with self._lock:
            self._flush()

    def _flush(self) -> None:
        if self._csv_fd is None:
            return
        self._last_flush = self._clock()
        text = self._csv_buf.getvalue()
        if text:
            _write_all(self._csv_fd, text.encode("utf-8"))
            self._csv_buf = io.StringIO()
        if self._can_writer is not None:
            t = self._can_text.getvalue()
            if t:
                _write_all(self._cap_fd, t.encode("ascii"))
                self._can_text.seek(0)
                self._can_text.truncate()
        elif self._cap_fd is not None and self._cap_buf:
            _write_all(self._cap_fd, bytes(self._cap_buf))
            self._cap_buf.clear()

    def close(self) -> None:
        """Flush and close the files (idempotent); taps called later are ignored."""
        self._closed.set()
        with self._lock:
            if self._csv_fd is None:
                return
            if self._can_writer is not None:
                self._can_writer.stop()      # writes the ASC end line into our buffer
            self._flush()
            os.close(self._csv_fd)
            if self._cap_fd is not None:
                os.close(self._cap_fd)
            self._csv_fd = self._cap_fd = None

    def __enter__(self) -> "Archive":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def run_archived(source, archive: Archive, duration_s: float | None = None, on_block=None,
                 clock=time.monotonic) -> dict[str, int]:
    """Run ``source`` into ``archive`` until it ends or ``duration_s`` (s) passed;
    ``on_block(block)`` sees every block too. Closes both; returns the source counters
    merged with the archive's."""
    t_end = None if duration_s is None else clock() + duration_s
    try:
        for block in source.blocks():
            archive.write(block)
            if on_block is not None:
                on_block(block)
            if t_end is not None and clock() >= t_end:
                break
    finally:
        source.close()
        archive.close()
    return {**source.counters, **archive.counters}
