"""Put decoded frames on the uniform sample grid: lost samples become invalid
placeholders, so gaps are flagged, never joined.

Time comes from the device, never from the host's clock while the device is heard: a
sample's grid index advances by one per frame. Between two good frames the number of
samples lost is decided, in this order, by

1. an outage (the port was closed and reopened, so the bytes sent meanwhile are gone):
   the caller's estimate from the clock (elapsed s x rate Hz minus the frames that did
   arrive), made exact by the sequence counter: the count closest to the estimate that
   agrees with the counter (exact while the clock errs by less than half a counter wrap,
   64 ms for a 1 kHz KVH), or the rounded estimate without a counter;
2. otherwise the bytes: a continuous byte stream (no byte skipped, no CRC failure
   between the two frames) means the device sent nothing in between, so the counter's
   jump d gives (d - 1) mod wrap lost frames (a device-side drop), and without a counter
   none; where bytes were skipped (garbage, a corrupted or truncated frame), they bound
   the loss: skipped bytes / frame length frames at most, and the counter picks the
   count closest to that among d - 1 + j x wrap (without a counter: the rounded ratio).

A host stall (CPU load, GC, a slow sink) therefore never creates a gap: the OS buffers
the bytes, and they arrive later but continuous.
"""
from __future__ import annotations

import numpy as np

from fogmon.block import Block, Event
from fogmon.errors import ERROR_COUNTERS
from fogmon.sources.frames import Frames

#: at most this many gap events per block; the rest are summarised in one event
MAX_GAP_EVENTS = 5
#: why samples were lost, by the rule that counted them (gap event messages)
_WHY = ("sequence counter", "bytes skipped", "port reopened")


def lost_frames(base: np.ndarray | None, skipped: np.ndarray, frame_bytes: int, modulus: int | None) -> np.ndarray:
    """Frames lost before each frame of a byte stream (rule 2 of the module doc): ``base``
    the counter's (d - 1) mod ``modulus`` (None without a counter), ``skipped`` the bytes
    skipped before each frame, ``frame_bytes`` the protocol's frame length (0 = unknown:
    skipped bytes then count nothing)."""
    skipped = np.asarray(skipped, dtype=np.int64)
    est = skipped / frame_bytes if frame_bytes else np.zeros(len(skipped))
    if base is None:
        return np.where(skipped > 0, np.rint(est), 0).astype(np.int64)
    j = np.maximum(0, np.rint((est - base) / modulus)).astype(np.int64)
    return np.where(skipped > 0, base + j * modulus, base).astype(np.int64)


class GridAssembler:
    """Frames -> Blocks on the grid ``t_s = t0_s + k / sample_rate_hz`` (s). Counters:
    ``seq_gaps`` (places where samples were lost), ``samples_missing`` (placeholders
    inserted), ``invalid_samples`` (frames the device flagged invalid). With ``axes``
    (frames and blocks with one rate/valid column per axis) ``invalid_samples`` counts
    frames with at least one axis invalid and ``invalid_samples_<axis>`` those of each
    axis; a lost frame is a placeholder on every axis."""

    def __init__(self, sample_rate_hz: float, seq_modulus: int | None, aux_names=(), t0_s: float = 0.0,
                 axes: tuple[str, ...] = ()) -> None:
        self.sample_rate_hz = float(sample_rate_hz)
        self.seq_modulus = seq_modulus
        self.aux_names = tuple(aux_names)
        self.axes = tuple(axes)
        self.t0_s = float(t0_s)
        self.next_index = 0          # grid index of the next sample
        self._started = False        # a frame has been placed
        self._last_seq: int | None = None
        self._break_est: float | None = None
        self.counters = {"seq_gaps": 0, "samples_missing": 0, "invalid_samples": 0,
                         **{f"invalid_samples_{a}": 0 for a in self.axes}}

    def mark_break(self, missing_est: float) -> None:
        """An outage before the next frame (the port was closed and reopened), in which
        about ``missing_est`` samples were lost (from the clock: elapsed s x rate Hz minus
        the frames that did arrive)."""
        self._break_est = float(missing_est)

    def _missing_before_first(self, seq0: int, skipped0: int, frame_bytes: int) -> tuple[int, int]:
        """(samples lost before the first frame of a push, index into _WHY)."""
        M = self.seq_modulus
        if not self._started:
            self._break_est = None
            return 0, 0
        if self._break_est is not None:
            est = max(0.0, self._break_est)
            self._break_est = None
            if M is None or seq0 < 0 or self._last_seq is None:
                return int(round(est)), 2
            base = (seq0 - self._last_seq - 1) % M  # missing = base + j*M for the j closest to est
            j = max(0, int(round((est - base) / M)))
            return base + j * M, 2
        last = self._last_seq
        base0 = np.array([(seq0 - last - 1) % M]) if M is not None and seq0 >= 0 and last is not None else None
        M_counted = M if base0 is not None else None
        return int(lost_frames(base0, np.array([skipped0]), frame_bytes, M_counted)[0]), int(skipped0 > 0)

    def push(self, frames: Frames, events: list[Event] | tuple = ()) -> Block:
        """Place ``frames`` on the grid; returns the block (possibly empty) with gap
        events plus the given ``events``."""
        n = len(frames)
        evs = list(events)
        shape = (len(self.axes),) if self.axes else ()
        if n == 0:
            t = np.zeros(0)
            return Block(t, np.zeros((0, *shape)), np.zeros((0, *shape), bool),
                         {k: np.zeros(0) for k in self.aux_names}, tuple(evs), self.axes)
        seq, skipped = frames.seq, frames.skipped_bytes()
        missing = np.zeros(n, dtype=np.int64)
        why = (skipped > 0).astype(np.int64)
        missing[0], why[0] = self._missing_before_first(int(seq[0]), int(skipped[0]), frames.frame_bytes)
        M = self.seq_modulus
        if n > 1:
            counted = M is not None and seq[0] >= 0
            base = (np.diff(seq) - 1) % M if counted else None
            missing[1:] = lost_frames(base, skipped[1:], frames.frame_bytes, M if counted else None)
        self._started = True
        self._last_seq = int(seq[-1]) if seq[-1] >= 0 else None
        offs = np.arange(n) + np.cumsum(missing)          # output position of each frame
        total = int(offs[-1]) + 1
        k0 = self.next_index
        t = self.t0_s + (k0 + np.arange(total)) / self.sample_rate_hz
        rate = np.full((total, *shape), np.nan)
        valid = np.zeros((total, *shape), bool)
        ok = frames.valid & np.isfinite(frames.rate_dph)
        rate[offs] = np.where(ok, frames.rate_dph, np.nan)
        valid[offs] = ok
        aux = {}
        for name in self.aux_names:
            a = np.full(total, np.nan)
            a[offs] = frames.aux[name]
            aux[name] = a
        gaps = np.flatnonzero(missing)
        c = self.counters
        c["seq_gaps"] += len(gaps)
        c["samples_missing"] += int(missing.sum())
        bad = ~ok
        c["invalid_samples"] += int(bad.any(axis=1).sum() if self.axes else bad.sum())
        for j, axis in enumerate(self.axes):
            c[f"invalid_samples_{axis}"] += int(bad[:, j].sum())
        for g in gaps[:MAX_GAP_EVENTS]:
            tg = float(t[offs[g] - missing[g]])
            evs.append(Event(tg, "gap", f"{int(missing[g])} sample(s) lost at t={tg:.6f} s ({_WHY[why[g]]})"))
        if len(gaps) > MAX_GAP_EVENTS:
            rest = gaps[MAX_GAP_EVENTS:]
            evs.append(Event(float(t[offs[rest[0]]]), "gap",
                             f"{len(rest)} more gaps, {int(missing[rest].sum())} samples lost in this block"))
        self.next_index = k0 + total
        return Block(t, rate, valid, aux, tuple(evs), self.axes)

    @property
    def t_next_s(self) -> float:
        """Grid time (s) of the next sample."""
        return self.t0_s + self.next_index / self.sample_rate_hz



class ErrorEvents:
    """Decoder error counters -> events: ``poll(t_s)`` returns one event per counter that
    grew since the last poll (so at most one per kind per block: rate-limited)."""

    def __init__(self, counters: dict[str, int]) -> None:
        self._counters = counters
        self._last = {k: counters.get(k, 0) for k in ERROR_COUNTERS if k in counters}

    def poll(self, t_s: float) -> list[Event]:
        out = []
        for k, last in self._last.items():
            now = self._counters[k]
            if now > last:
                kind, what = ERROR_COUNTERS[k]
                out.append(Event(t_s, kind, f"{now - last} {what} ({now} so far)"))
                self._last[k] = now
        return out
