"""Replay sources: a replay-log CSV (CONTRACT section 1) and a raw serial capture (the
bytes a device sent, decoded again with its protocol). Both yield the same blocks a live
source would, as fast as they can (the pipeline paces ``--realtime``; a replay log can
also pace itself for use outside it).

A raw capture ``X`` may have a sidecar ``X.json`` (written by the archive) naming the
protocol and decoder options and the outages seen while recording
(``"breaks": [{"offset": byte offset, "missing_est": samples, "elapsed_s": s}, ...]``), so that replaying it
gives exactly the samples the live monitor saw."""
from __future__ import annotations

import functools
import json
import os
from typing import Iterator

import numpy as np

from fogmon.block import Block, Event
from fogmon.errors import FogmonError
from fogmon.recording import read_replay_log
from fogmon.sources.codecs import codec_from_options
from fogmon.sources.grid import MAX_GAP_EVENTS, ErrorEvents, GridAssembler
from fogmon.sources.pacing import Pacer

#: samples per block when replaying as fast as possible
FAST_BLOCK = 8192
#: block length (s) when paced
PACED_BLOCK_S = 0.1
SIDECAR_SUFFIX = ".json"
CAPTURE_FORMAT = "fogmon capture v1"


def _block_len(rate_hz: float, speed: float | None) -> int:
    return FAST_BLOCK if not speed else max(1, int(round(PACED_BLOCK_S * rate_hz * speed)))


class ReplayLogSource:
    """A replay-log CSV on its uniform grid: time gaps become invalid placeholders with a
    ``gap`` event. Counters: ``samples`` (rows), ``samples_missing``, ``seq_gaps``
    (time gaps), ``skipped_rows`` (only with ``tolerate=True``)."""

    def __init__(self, path: str, speed: float | None = None, tolerate: bool = False) -> None:
        rec = read_replay_log(path, tolerate=tolerate)
        self.recording = rec
        self.rate_hz = rec.sample_rate_hz
        self._block = rec.to_block()
        present = np.zeros(len(self._block), bool)
        present[rec.grid_index()] = True
        self._present = present
        self.name = f"replay log {rec.name}" + (f" ({rec.meta['sensor']})" if "sensor" in rec.meta else "")
        starts = np.flatnonzero(~present[1:] & present[:-1]) + 1 if len(present) > 1 else np.zeros(0, int)
        self.counters = {"samples": len(rec), "samples_missing": int((~present).sum()),
                         "seq_gaps": len(starts), "skipped_rows": rec.skipped_rows}
        self._pacer = Pacer(speed)
        self._n = _block_len(self.rate_hz, speed)
        self._closed = False

    def blocks(self) -> Iterator[Block]:
        b, present = self._block, self._present
        for i in range(0, len(b), self._n):
            if self._closed:
                return
            sl = slice(i, i + self._n)
            t = b.t_s[sl]
            self._pacer.wait(float(t[0]))
            yield Block(t, b.rate_dph[sl], b.valid[sl], {k: v[sl] for k, v in b.aux.items()},
                        _gap_events(t, ~present[sl], i > 0 and not present[i - 1]))

    def close(self) -> None:
        self._closed = True


def _gap_events(t: np.ndarray, missing: np.ndarray, continues: bool) -> tuple[Event, ...]:
    """Events for each run of missing samples starting in this block."""
    m = missing.astype(np.int8)
    edges = np.diff(np.concatenate([[1 if continues else 0], m, [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    if continues and len(ends) and (not len(starts) or ends[0] < starts[0]):
        ends = ends[1:]
    evs = [Event(float(t[s]), "gap", f"{int(e - s)} sample(s) missing at t={t[s]:.6f} s (time gap in the log)")
           for s, e in zip(starts[:MAX_GAP_EVENTS], ends[:MAX_GAP_EVENTS])]
    if len(starts) > MAX_GAP_EVENTS:
        evs.append(Event(float(t[starts[MAX_GAP_EVENTS]]), "gap", f"{len(starts) - MAX_GAP_EVENTS} more gaps in this block"))
    return tuple(evs)


def read_sidecar(path: str) -> dict | None:
    """The capture sidecar ``path + '.json'`` as a dict, or None when there is none."""
    side = path + SIDECAR_SUFFIX
    if not os.path.exists(side):
        return None
    try:
        with open(side, encoding="utf-8") as fh:
            d = json.load(fh)
    except (OSError, ValueError) as e:
        raise FogmonError(f"{side}: not a readable capture sidecar ({e})") from None
    if not isinstance(d, dict) or d.get("format") != CAPTURE_FORMAT:
        raise FogmonError(f"{side}: not a fogmon capture sidecar (missing \"format\": \"{CAPTURE_FORMAT}\")")
    return d


class RawCaptureSource:
    """Bytes a serial device sent, decoded again. ``options`` are the decoder options
    (``protocol``, ``rate_hz``, ``kvh_rot``, ``kvh_units``, ``axis``, ``columns``);
    ``breaks`` the outages [(byte offset, estimated samples lost)]. Counters: the decoder's and the
    grid's (see GridAssembler)."""

    CHUNK = 1 << 16

    def __init__(self, path: str, options: dict, breaks=()) -> None:
        if not os.path.isfile(path):
            raise FogmonError(f"{path}: no such file")
        self.path = path
        self._options = dict(options)
        self.codec = codec_from_options(options)
        self.rate_hz = self.codec.rate_hz
        self.grid = GridAssembler(self.rate_hz, self.codec.seq_modulus, self.codec.aux_names)
        self.name = f"raw capture {os.path.basename(path)}: {self.codec.describe()}"
        self._breaks = sorted((int(o), float(e)) for o, e in breaks)
        self._closed = False

    @property
    def counters(self) -> dict[str, int]:
        return {**self.codec.counters, **self.grid.counters}

    @functools.cached_property
    def n_samples(self) -> int:
        """Samples on the grid, from a counting pass over the file (pipelines size their
        default window with it)."""
        return sum(len(b) for b in RawCaptureSource(self.path, self._options, self._breaks).blocks())

    def blocks(self) -> Iterator[Block]:
        pos = 0
        breaks = list(self._breaks)
        chunk = self.CHUNK
        try:
            fh = open(self.path, "rb")
        except OSError as e:
            raise FogmonError(f"{self.path}: cannot read: {e.strerror}") from None
        errors = ErrorEvents(self.codec.counters)
        with fh:
            while not self._closed:
                end = pos + chunk
                if breaks and breaks[0][0] <= end:
                    end = breaks[0][0]
                data = fh.read(end - pos)
                at_break = bool(breaks) and pos + len(data) == breaks[0][0]
                if not data and not at_break:
                    return
                pos += len(data)
                frames = self.codec.feed(data)
                if len(frames):
                    yield self.grid.push(frames, errors.poll(self.grid.t_next_s))
                if at_break:
                    off, est = breaks.pop(0)
                    self.grid.mark_break(est)

    def close(self) -> None:
        self._closed = True


def open_raw_capture(path: str, overrides: dict | None = None) -> RawCaptureSource:
    """A raw capture with options from its sidecar, overridden by ``overrides`` (the
    command line); without a sidecar ``overrides['protocol']`` is required."""
    side = read_sidecar(path) or {}
    opts = {k: side[k] for k in ("protocol", "rate_hz", "kvh_rot", "kvh_units", "axis", "columns") if k in side}
    opts.update({k: v for k, v in (overrides or {}).items() if v is not None})
    if "protocol" not in opts:
        raise FogmonError(f"{path}: a raw serial capture needs --protocol "
                          f"(or a {os.path.basename(path)}{SIDECAR_SUFFIX} sidecar naming it)")
    try:
        breaks = [(int(b["offset"]), float(b["missing_est"])) for b in side.get("breaks", [])]
    except (KeyError, TypeError, ValueError):
        raise FogmonError(f"{path}{SIDECAR_SUFFIX}: field breaks: each needs offset and missing_est") from None
    return RawCaptureSource(path, opts, breaks)
