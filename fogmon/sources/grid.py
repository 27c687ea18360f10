"""Put decoded frames on the uniform sample grid: lost samples become invalid
placeholders, so gaps are flagged, never joined.

A sample's grid index advances by one per frame; when the device's sequence counter
jumps by d (modulo its wrap), d - 1 placeholders (valid False, rate and aux NaN) are
inserted. After an outage (port unplugged, CAN bus lost, a silent stretch in a log) the
caller estimates from the clock how many samples were lost; the number inserted is then
the count closest to that estimate that agrees with the counter (exact while the clock
is within half a counter wrap), or the rounded estimate without a counter.
"""
from __future__ import annotations

import numpy as np

from fogmon.block import Block, Event
from fogmon.errors import ERROR_COUNTERS
from fogmon.sources.frames import Frames

#: at most this many gap events per block; the rest are summarised in one event
MAX_GAP_EVENTS = 5


class GridAssembler:
    """Frames -> Blocks on the grid ``t_s = t0_s + k / rate_hz`` (s). Counters:
    ``seq_gaps`` (counter jumps and outages), ``samples_missing`` (placeholders
    inserted), ``invalid_samples`` (frames the device flagged invalid)."""

    def __init__(self, rate_hz: float, seq_modulus: int | None, aux_names=(), t0_s: float = 0.0) -> None:
        self.rate_hz = float(rate_hz)
        self.seq_modulus = seq_modulus
        self.aux_names = tuple(aux_names)
        self.t0_s = float(t0_s)
        self.next_index = 0          # grid index of the next sample
        self._last_seq: int | None = None
        self._break_est: float | None = None
        self.counters = {"seq_gaps": 0, "samples_missing": 0, "invalid_samples": 0}

    def mark_break(self, missing_est: float) -> None:
        """An outage before the next frame, in which about ``missing_est`` samples were
        lost (from the clock: elapsed s x rate Hz minus the frames that did arrive)."""
        self._break_est = float(missing_est)

    def _missing_before_first(self, seq0: int) -> int:
        M = self.seq_modulus
        if self._last_seq is None and self._break_est is None:
            return 0
        if self._break_est is not None:
            est = max(0.0, self._break_est)
            self._break_est = None
            if M is None or seq0 < 0 or self._last_seq is None:
                return int(round(est))
            d = (seq0 - self._last_seq) % M  # missing = d - 1 + j*M for the j closest to est
            base = (d - 1) % M
            j = max(0, int(round((est - base) / M)))
            return base + j * M
        if M is None or seq0 < 0:
            return 0
        d = (seq0 - self._last_seq) % M
        return (d - 1) % M

    def push(self, frames: Frames, events: list[Event] | tuple = ()) -> Block:
        """Place ``frames`` on the grid; returns the block (possibly empty) with gap
        events plus the given ``events``."""
        n = len(frames)
        evs = list(events)
        if n == 0:
            t = np.zeros(0)
            return Block(t, t.copy(), np.zeros(0, bool), {k: np.zeros(0) for k in self.aux_names}, tuple(evs))
        seq = frames.seq
        missing = np.zeros(n, dtype=np.int64)
        missing[0] = self._missing_before_first(int(seq[0]))
        M = self.seq_modulus
        if M is not None and n > 1 and seq[0] >= 0:
            missing[1:] = (np.diff(seq) - 1) % M
        self._last_seq = int(seq[-1]) if seq[-1] >= 0 else None
        offs = np.arange(n) + np.cumsum(missing)          # output position of each frame
        total = int(offs[-1]) + 1
        k0 = self.next_index
        t = self.t0_s + (k0 + np.arange(total)) / self.rate_hz
        rate = np.full(total, np.nan)
        valid = np.zeros(total, bool)
        rate[offs] = frames.rate_dph
        valid[offs] = frames.valid & np.isfinite(frames.rate_dph)
        rate[offs[~valid[offs]]] = np.nan
        aux = {}
        for name in self.aux_names:
            a = np.full(total, np.nan)
            a[offs] = frames.aux[name]
            aux[name] = a
        gaps = np.flatnonzero(missing)
        c = self.counters
        c["seq_gaps"] += len(gaps)
        c["samples_missing"] += int(missing.sum())
        c["invalid_samples"] += int(n - valid[offs].sum())
        for g in gaps[:MAX_GAP_EVENTS]:
            tg = float(t[offs[g] - missing[g]])
            evs.append(Event(tg, "gap", f"{int(missing[g])} sample(s) lost at t={tg:.6f} s "
                                        f"(sequence counter or outage)"))
        if len(gaps) > MAX_GAP_EVENTS:
            rest = gaps[MAX_GAP_EVENTS:]
            evs.append(Event(float(t[offs[rest[0]]]), "gap",
                             f"{len(rest)} more gaps, {int(missing[rest].sum())} samples lost in this block"))
        self.next_index = k0 + total
        return Block(t, rate, valid, aux, tuple(evs))

    @property
    def t_next_s(self) -> float:
        """Grid time (s) of the next sample."""
        return self.t0_s + self.next_index / self.rate_hz


def concat_blocks(blocks: list[Block]) -> Block:
    """Consecutive blocks of one grid as one block."""
    if len(blocks) == 1:
        return blocks[0]
    return Block(np.concatenate([b.t_s for b in blocks]), np.concatenate([b.rate_dph for b in blocks]),
                 np.concatenate([b.valid for b in blocks]),
                 {k: np.concatenate([b.aux[k] for b in blocks]) for k in blocks[0].aux},
                 tuple(e for b in blocks for e in b.events))


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
