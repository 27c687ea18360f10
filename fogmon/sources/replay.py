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
import math
import os
from typing import Iterator, Sequence

import numpy as np

from fogmon.block import Block, Event
from fogmon.errors import FogmonError
from fogmon.recording import read_replay_log
from fogmon.sources import plausibility
from fogmon.sources.codecs import OPTION_KEYS, PROTOCOLS, codec_from_options
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
    (time gaps), ``skipped_rows`` (only with ``tolerate=True``), ``implausible_samples``
    (rates beyond +-``max_abs_dph`` deg/h: made invalid, with an ``implausible`` event)."""

    def __init__(self, path: str, speed: float | None = None, tolerate: bool = False,
                 max_abs_dph: float = plausibility.GENERIC_MAX_ABS_DPH) -> None:
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
                         "seq_gaps": len(starts), "skipped_rows": rec.skipped_rows, plausibility.COUNTER: 0}
        self.max_abs_dph = float(max_abs_dph)
        self._pacer = Pacer(speed)
        self._n = _block_len(self.rate_hz, speed)
        self._closed = False

    def blocks(self) -> Iterator[Block]:
        b, present = self._block, self._present
        errors = ErrorEvents(self.counters)
        for i in range(0, len(b), self._n):
            if self._closed:
                return
            sl = slice(i, i + self._n)
            t = b.t_s[sl]
            self._pacer.wait(float(t[0]))
            rate, n_bad = plausibility.gate(b.rate_dph[sl], self.max_abs_dph)
            self.counters[plausibility.COUNTER] += n_bad
            t_bad = float(t[np.argmax(np.isnan(rate) & b.valid[sl])])    # the first implausible sample's
            events = _gap_events(t, ~present[sl], i > 0 and not present[i - 1]) + tuple(errors.poll(t_bad))
            yield Block(t, rate, b.valid[sl] & ~np.isnan(rate), {k: v[sl] for k, v in b.aux.items()}, events)

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


#: The decoder options a serial capture's sidecar may hold (names of codec options()).
DECODER_FIELDS = OPTION_KEYS


def _text(v, folder):
    return None if isinstance(v, str) else f"expected text, got {v!r}"


def _text_or_null(v, folder):
    return None if v is None or isinstance(v, str) else f"expected text or null, got {v!r}"


def _one_of(*values):
    def check(v, folder):
        return None if v in values else f"expected one of {', '.join(map(str, values))}, got {v!r}"
    return check


def _number(minimum: float, strict: bool):
    def check(v, folder):
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and \
            (v > minimum if strict else v >= minimum)
        return None if ok else f"expected a number {'>' if strict else '>='} {minimum:g}, got {v!r}"
    return check


def _count(v, folder):
    return None if isinstance(v, int) and not isinstance(v, bool) and v >= 0 else \
        f"expected a whole number >= 0, got {v!r}"


def _file_in_folder(v, folder):
    """A file named by the sidecar must be in the sidecar's own folder: a plain file name,
    not a path (absolute, with .., or through a link leading elsewhere)."""
    if not isinstance(v, str) or not v or v in (".", "..") or os.path.basename(v) != v or "\\" in v:
        return f"must name a file in the sidecar's folder ({folder}), got {v!r}"
    real = os.path.realpath(os.path.join(folder, v))
    if os.path.dirname(real) != os.path.realpath(folder):
        return f"{v!r} leads outside the sidecar's folder ({folder})"
    return None


def _breaks(v, folder):
    if not isinstance(v, list):
        return f"expected a list, got {v!r}"
    for i, b in enumerate(v):
        if not (isinstance(b, dict) and "offset" in b and "missing_est" in b and _count(b["offset"], folder) is None
                and _number(0, False)(b["missing_est"], folder) is None):
            return f"item {i}: expected {{\"offset\": bytes >= 0, \"missing_est\": samples >= 0}}, got {b!r}"
    return None


#: Sidecar fields -> check (None if fine, else why not). ``format`` and ``kind`` are
#: required; unknown fields are ignored (newer writers may add some).
SIDECAR_FIELDS = {
    "kind": _one_of("serial", "can"), "protocol": _one_of(*PROTOCOLS), "rate_hz": _number(0, True),
    "kvh_rot": _one_of("rate", "delta"), "kvh_units": _one_of("deg", "rad"), "axis": _one_of("x", "y", "z"),
    "columns": _text, "max_rate_dph": _number(0, True), "breaks": _breaks, "piece": _count, "started_utc": _text,
    "port": _text, "baud": _count, "channel": _text_or_null, "interface": _text_or_null, "dbc": _file_in_folder,
    "message": _text_or_null, "rate_signal": _text_or_null, "rate_unit": _text_or_null,
    "temp_signal": _text_or_null, "counter_signal": _text_or_null, "valid_signal": _text_or_null,
}


def read_sidecar(path: str) -> dict | None:
    """The capture sidecar ``path + '.json'`` as a dict (checked field by field: a bad
    one is a one-line FogmonError naming the file and the field), or None when there is
    none."""
    side = path + SIDECAR_SUFFIX
    if not os.path.exists(side):
        return None
    try:
        with open(side, encoding="utf-8") as fh:
            d = json.load(fh)
    except OSError as e:
        raise FogmonError(f"{side}: not a readable capture sidecar ({e.strerror})") from None
    except ValueError as e:
        raise FogmonError(f"{side}: not a readable capture sidecar (bad JSON: {e})") from None
    if not isinstance(d, dict) or d.get("format") != CAPTURE_FORMAT:
        raise FogmonError(f"{side}: not a fogmon capture sidecar (missing \"format\": \"{CAPTURE_FORMAT}\")")
    if "kind" not in d:
        raise FogmonError(f"{side}: field kind: missing")
    folder = os.path.dirname(os.path.abspath(side))
    for name, check in SIDECAR_FIELDS.items():
        why = check(d[name], folder) if name in d else None
        if why:
            raise FogmonError(f"{side}: field {name}: {why}")
    return d


class RawCaptureSource:
    """Bytes a serial device sent, decoded again. ``path`` is one capture file or the
    pieces of one (an archive's raw-NNNN.bin), read in order as one byte stream, so the
    decoder's state (a frame split across two pieces, the sequence counter) carries
    across. ``options`` are the decoder options (``protocol``, ``rate_hz``, ``kvh_rot``,
    ``kvh_units``, ``axis``, ``columns``); ``breaks`` the outages [(byte offset in the
    stream, estimated samples lost)]. Counters: the decoder's and the grid's (see
    GridAssembler)."""

    CHUNK = 1 << 16

    def __init__(self, path: str | Sequence[str], options: dict, breaks=()) -> None:
        self.paths = [path] if isinstance(path, str) else list(path)
        for p in self.paths:
            if not os.path.isfile(p):
                raise FogmonError(f"{p}: no such file")
        self._options = dict(options)
        self.codec = codec_from_options(options)
        self.rate_hz = self.codec.rate_hz
        self.grid = GridAssembler(self.rate_hz, self.codec.seq_modulus, self.codec.aux_names)
        what = os.path.basename(self.paths[0]) + (
            f" .. {os.path.basename(self.paths[-1])} ({len(self.paths)} pieces)" if len(self.paths) > 1 else "")
        self.name = f"raw capture {what}: {self.codec.describe()}"
        self._breaks = sorted((int(o), float(e)) for o, e in breaks)
        self._closed = False

    @property
    def counters(self) -> dict[str, int]:
        return {**self.codec.counters, **self.grid.counters}

    @functools.cached_property
    def n_samples(self) -> int:
        """Samples on the grid, from a counting pass over the file(s) (pipelines size their
        default window with it)."""
        return sum(len(b) for b in RawCaptureSource(self.paths, self._options, self._breaks).blocks())

    def blocks(self) -> Iterator[Block]:
        pos = 0
        breaks = list(self._breaks)
        errors = ErrorEvents(self.codec.counters)
        for path in self.paths:
            try:
                fh = open(path, "rb")
            except OSError as e:
                raise FogmonError(f"{path}: cannot read: {e.strerror}") from None
            with fh:
                while not self._closed:
                    end = pos + self.CHUNK
                    if breaks and breaks[0][0] <= end:
                        end = breaks[0][0]
                    data = fh.read(end - pos)
                    at_break = bool(breaks) and pos + len(data) == breaks[0][0]
                    if not data and not at_break:
                        break
                    pos += len(data)
                    frames = self.codec.feed(data)
                    if len(frames):
                        yield self.grid.push(frames, errors.poll(self.grid.t_next_s))
                    if at_break:
                        off, est = breaks.pop(0)
                        self.grid.mark_break(est)

    def close(self) -> None:
        self._closed = True


def open_raw_capture(path: str | Sequence[str], overrides: dict | None = None) -> RawCaptureSource:
    """A raw capture (or the pieces of one, in order) with the decoder options of its
    sidecar(s), overridden by ``overrides`` (the command line); without a sidecar
    ``overrides['protocol']`` is required. Pieces must agree on the decoder options;
    their outages are placed in the joined byte stream."""
    paths = [path] if isinstance(path, str) else list(path)
    opts: dict | None = None
    breaks, offset = [], 0
    for p in paths:
        side = read_sidecar(p) or {}
        piece_opts = {k: side[k] for k in DECODER_FIELDS if k in side}
        if opts is None:
            opts = piece_opts
        elif piece_opts != opts:
            raise FogmonError(f"{p}{SIDECAR_SUFFIX}: decoder options {piece_opts} differ from those of "
                              f"{paths[0]}{SIDECAR_SUFFIX} ({opts}): not pieces of one capture")
        breaks += [(offset + b["offset"], float(b["missing_est"])) for b in side.get("breaks", [])]
        try:
            offset += os.path.getsize(p)
        except OSError:
            raise FogmonError(f"{p}: no such file") from None
    opts.update({k: v for k, v in (overrides or {}).items() if v is not None})
    if "protocol" not in opts:
        raise FogmonError(f"{paths[0]}: a raw serial capture needs --protocol "
                          f"(or a {os.path.basename(paths[0])}{SIDECAR_SUFFIX} sidecar naming it)")
    return RawCaptureSource(paths, opts, breaks)


class ReplayLogSet:
    """Replay-log pieces (an archive's samples-NNNN.csv, fogmon.pieces) replayed as one
    recording, one piece in memory at a time. The sample grid goes on across the seams:
    samples missing between two pieces become invalid placeholders with a ``gap`` event,
    as inside one log; pieces that overlap in time, or differ in sample rate or columns,
    are a one-line error. Counters: the pieces' summed, seam gaps included."""

    def __init__(self, paths: Sequence[str], tolerate: bool = False,
                 max_abs_dph: float = plausibility.GENERIC_MAX_ABS_DPH) -> None:
        self.paths, self._tolerate, self._max_abs_dph = list(paths), tolerate, max_abs_dph
        self._first = ReplayLogSource(self.paths[0], tolerate=tolerate, max_abs_dph=max_abs_dph)
        self.rate_hz = self._first.rate_hz
        self.name = f"replay log {os.path.basename(self.paths[0])} .. {os.path.basename(self.paths[-1])} " \
                    f"({len(self.paths)} pieces)"
        self.counters = {k: 0 for k in self._first.counters}
        t0 = float(self._first.recording.t_s[0])
        t_last = float(read_replay_log(self.paths[-1], tolerate=tolerate).t_s[-1])
        self.n_samples = int(round((t_last - t0) * self.rate_hz)) + 1
        self._closed = False

    def blocks(self) -> Iterator[Block]:
        t_end = aux = None
        for i, path in enumerate(self.paths):
            src = self._first if i == 0 else ReplayLogSource(path, tolerate=self._tolerate,
                                                             max_abs_dph=self._max_abs_dph)
            if src.rate_hz != self.rate_hz:
                raise FogmonError(f"{path}: sample_rate_hz {src.rate_hz:g} differs from {self.paths[0]} "
                                  f"({self.rate_hz:g} Hz): not pieces of one recording")
            for b in src.blocks():
                if self._closed:
                    return
                if aux is None:
                    aux = list(b.aux)
                if list(b.aux) != aux:
                    raise FogmonError(f"{path}: columns {list(b.aux)} differ from {self.paths[0]} ({aux})")
                if t_end is not None:
                    missing = int(round((b.t_s[0] - t_end) * self.rate_hz)) - 1
                    if missing < 0:
                        raise FogmonError(f"{path}: starts at t={b.t_s[0]:.6f} s, not after the end of the "
                                          f"previous piece (t={t_end:.6f} s)")
                    if missing:
                        for k, v in (("samples_missing", missing), ("seq_gaps", 1)):
                            self.counters[k] = self.counters.get(k, 0) + v
                        yield _seam_gap(t_end, missing, self.rate_hz, aux)
                t_end = float(b.t_s[-1])
                yield b
            for k, v in src.counters.items():
                self.counters[k] = self.counters.get(k, 0) + v

    def close(self) -> None:
        self._closed = True


def _seam_gap(t_end: float, missing: int, rate_hz: float, aux: list[str]) -> Block:
    """Invalid placeholders for the samples missing between two pieces, with a gap event."""
    t = t_end + np.arange(1, missing + 1) / rate_hz
    nan = np.full(missing, np.nan)
    return Block(t, nan, np.zeros(missing, bool), {k: nan for k in aux},
                 (Event(float(t[0]), "gap", f"{missing} sample(s) missing at t={t[0]:.6f} s (between two pieces)"),))
