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

3. the host clock, for a live byte stream (``observe_clock``, at every read that found
   nothing more waiting): when frames vanish whole (an OS buffer overrun at frame
   boundaries, a device-side drop of a whole counter wrap or more) neither the bytes nor
   the counter can tell, and the grid falls behind the host clock by whole wraps, in one
   step. When it steps back by half a wrap or more from one look to the next and then
   stays there, varying by less than half a wrap, for CLOCK_CONFIRM_S, the whole wraps of
   that step are placed before the next frame (a ``gap`` event by the host clock, counted
   as ``clock_wraps``): a shift of a whole wrap never passes silently. The samples
   between the loss and that point sit early by those wraps (the event says since when).
   A device that sends late catches up (the lag shrinks) and one slower than its rate
   falls behind gradually (no step): neither is taken for a loss. Assumed: the bytes
   reach the host's buffer less than half a wrap after the device sent them (a device
   buffers no more).

Plausible gaps only: every count that sizes an array is checked first. The gaps of one
push may hold at most ``max_gap`` samples (``gap_limit``: what the time the source can
vouch for holds; by default MAX_GAP_S, at most MAX_GAP_SAMPLES); a counter jump beyond
it is no loss but a counter reset or a corrupt counter: an ``implausible`` event,
counted as ``implausible_gaps``, and only what the skipped bytes say is placed. An
outage estimate beyond it is a FogmonError: no sample grid bridges it.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from fogmon.block import Block, Event
from fogmon.errors import ERROR_COUNTERS, FogmonError
from fogmon.sources.frames import Frames

#: at most this many gap events per block; the rest are summarised in one event
MAX_GAP_EVENTS = 5
#: why samples were lost, by the rule that counted them (gap event messages); ``Placed.rule``
#: and a capture sidecar's ``rule`` are indices into it (IMPLAUSIBLE: the bytes' count where
#: the counter's jump was implausible)
WHY = ("sequence counter", "bytes skipped", "port reopened", "host clock",
       "bytes skipped; the counter jump implausible")
SEQUENCE, BYTES, REOPENED, HOST_CLOCK, IMPLAUSIBLE = range(5)
#: the highest sample rate (Hz) a source may have: beyond it a rate is a typo or a corrupt field
MAX_SAMPLE_RATE_HZ = 1e6
#: the longest gap (s) a source may place without a clock that vouches for more, and at
#: most this many samples in any case (2**24 placeholders: 0.3 GB for three axes with
#: four aux channels)
MAX_GAP_S = 3600.0
MAX_GAP_SAMPLES = 2**24
#: the grid must stay behind the host clock by half a counter wrap or more, varying by
#: less than half a wrap, for this long (s) and over at least CLOCK_CONFIRM_N looks, before
#: the clock's whole wraps are placed: a late read (USB latency, a busy host) is over
#: sooner, and a device that sends late catches up (the lag shrinks) meanwhile
CLOCK_CONFIRM_S = 0.5
CLOCK_CONFIRM_N = 4
#: the device may run this much slower than ``sample_rate_hz`` (relative) without a wrap
#: being inferred: ten times a crystal's 100 ppm
CLOCK_DRIFT = 1e-3


def check_sample_rate(sample_rate_hz: float, name: str = "sample_rate_hz") -> float:
    """``sample_rate_hz`` as a float if it is a number > 0 and at most MAX_SAMPLE_RATE_HZ,
    else a FogmonError naming the parameter ``name``."""
    try:
        rate = float(sample_rate_hz)
    except (TypeError, ValueError):
        rate = math.nan
    if not 0 < rate <= MAX_SAMPLE_RATE_HZ:
        got = f"{rate:g}" if not math.isnan(rate) else repr(sample_rate_hz)
        raise FogmonError(f"`{name}` must be > 0 and at most {MAX_SAMPLE_RATE_HZ:,.0f} Hz, got {got}")
    return rate


def gap_limit(sample_rate_hz: float, span_s: float = MAX_GAP_S, seq_modulus: int | None = None) -> int:
    """The most samples the gaps between two frames can hold when at most ``span_s`` s can
    have passed between them: s x Hz (at most MAX_GAP_SAMPLES), plus one counter wrap
    (``seq_modulus``, when no larger than that) for the counter's rounding, plus one."""
    n = min(max(float(span_s), 0.0) * sample_rate_hz, MAX_GAP_SAMPLES)
    wrap = seq_modulus if seq_modulus is not None and seq_modulus <= MAX_GAP_SAMPLES else 0
    return int(n) + wrap + 1


#: the most samples any one gap may hold, whatever a source's clock says
GAP_CEILING = gap_limit(1.0, math.inf, MAX_GAP_SAMPLES)


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


def _beyond(missing: np.ndarray, limit: int) -> np.ndarray:
    """Which gaps are beyond ``limit``: alone, or by taking the sum of the gaps so far
    beyond it."""
    capped = np.minimum(missing, GAP_CEILING)        # (a wrap of 2**62 would overflow the sum)
    alone = capped > limit
    return alone | ((capped > 0) & (np.cumsum(np.where(alone, 0, capped)) > limit))


class Placed(NamedTuple):
    """A gap the grid placed by a live source's clock, which the bytes alone would not
    give again: ``missing`` samples before frame ``frame`` (0-based, of the push that
    placed it, or counted from ``GridAssembler.place``), by rule ``rule`` (an index of
    WHY), ``wraps`` of them whole counter wraps the host clock found."""

    frame: int
    missing: int
    rule: int
    wraps: int = 0


class GridAssembler:
    """Frames -> Blocks on the grid ``t_s = t0_s + k / sample_rate_hz`` (s). Counters:
    ``seq_gaps`` (places where samples were lost), ``samples_missing`` (placeholders
    inserted), ``invalid_samples`` (frames the device flagged invalid),
    ``implausible_gaps`` (counter jumps beyond ``max_gap``, not placed) and, with a
    counter, ``clock_wraps`` (whole counter wraps the host clock found). With ``axes``
    (frames and blocks with one rate/valid column per axis) ``invalid_samples`` counts
    frames with at least one axis invalid and ``invalid_samples_<axis>`` those of each
    axis; a lost frame is a placeholder on every axis.

    ``max_gap`` (samples) bounds the gaps of the next push (None: ``gap_limit`` of
    MAX_GAP_S). A live source sets it from its clock before each push and calls
    ``observe_clock``; ``decisions`` then lists what the last push placed by the clock
    (``Placed``), so that a replay of its capture places the same (``place``)."""

    def __init__(self, sample_rate_hz: float, seq_modulus: int | None, aux_names=(), t0_s: float = 0.0,
                 axes: tuple[str, ...] = ()) -> None:
        self.sample_rate_hz = check_sample_rate(sample_rate_hz)
        self.seq_modulus = seq_modulus
        self.aux_names = tuple(aux_names)
        self.axes = tuple(axes)
        self.t0_s = float(t0_s)
        self.next_index = 0          # grid index of the next sample
        self.max_gap: int | None = None
        self.decisions: list[Placed] = []
        self._default_gap = gap_limit(self.sample_rate_hz, MAX_GAP_S, seq_modulus)
        self._started = False        # a frame has been placed
        self._last_seq: int | None = None
        self._break_est: float | None = None
        self._frames_in = 0          # frames pushed so far
        self._placed: tuple[Placed, ...] = ()   # to place, frame counted from the first frame pushed
        # the host clock (rule 3): the baseline (samples the grid is behind the clock, + a
        # constant) and when it was set (host s); the previous look (excess over the
        # baseline, grid t_s); a step up (the excess before it, grid t_s before it, host s
        # of the first look after it) and the looks since (host s, excess); wraps due
        self._clk_base: float | None = None
        self._clk_t = 0.0
        self._clk_prev = (0.0, 0.0)
        self._clk_step: tuple[float, float, float] | None = None
        self._clk_up: tuple[tuple[float, float], ...] = ()
        self._wraps: tuple[int, float] | None = None
        self.counters = {"seq_gaps": 0, "samples_missing": 0, "invalid_samples": 0,
                         **{f"invalid_samples_{a}": 0 for a in self.axes}, "implausible_gaps": 0}
        if seq_modulus is not None:
            self.counters["clock_wraps"] = 0

    def mark_break(self, missing_est: float) -> None:
        """An outage before the next frame (the port was closed and reopened), in which
        about ``missing_est`` samples were lost (from the clock: elapsed s x rate Hz minus
        the frames that did arrive). A FogmonError when more than a gap may hold
        (``gap_limit`` of MAX_GAP_S)."""
        est = float(missing_est)
        if not 0 <= est <= self._default_gap:
            raise FogmonError(f"an outage of {est:.6g} samples ({est / self.sample_rate_hz:.6g} s at "
                              f"{self.sample_rate_hz:g} Hz) after t={self.t_next_s:.6f} s: more than one gap on a "
                              f"sample grid may hold ({self._default_gap} samples)")
        self._break_est = est
        self._clk_base = None        # the outage's count came from the clock: look afresh

    def place(self, placed: Placed) -> None:
        """Place ``placed.missing`` samples before the ``placed.frame``-th frame pushed from
        now on, whatever rules 1-2 say: what a live run decided by its clock, replayed from
        its capture. A FogmonError for an impossible count or rule."""
        p = Placed(*(int(v) for v in placed))
        if not (0 <= p.missing <= GAP_CEILING and p.frame >= 0 and 0 <= p.rule < len(WHY) and p.wraps >= 0):
            raise FogmonError(f"cannot place {p.missing} samples before frame {p.frame} by rule {p.rule} (at most "
                              f"{GAP_CEILING} samples, rules 0..{len(WHY) - 1})")
        self._placed = tuple(sorted((*self._placed, p._replace(frame=self._frames_in + p.frame))))

    # -- the host clock (rule 3) -----------------------------------------------------------
    def observe_clock(self, t_host_s: float) -> None:
        """The stream up to the last frame pushed had been read in full at host clock time
        ``t_host_s`` (s: a read found nothing more waiting); compare the grid with the
        clock (rule 3 of the module doc). Only with a counter, whose rule can under-count
        by whole wraps."""
        M = self.seq_modulus
        if M is None or M > MAX_GAP_SAMPLES or not self._started:
            return
        behind = t_host_s * self.sample_rate_hz - self.next_index
        base = self._clk_base
        if base is None or behind <= base:        # the first look, or the stream ahead of the baseline
            self._clk_base, self._clk_t, self._clk_prev = behind, t_host_s, (0.0, self.t_next_s)
            self._clk_step, self._clk_up = None, ()
            return
        excess = behind - base
        before, self._clk_prev = self._clk_prev, (excess, self.t_next_s)
        if excess < M / 2:                        # no wrap lost; the baseline follows a slow drift
            self._clk_base = min(behind, base + CLOCK_DRIFT * self.sample_rate_hz * (t_host_s - self._clk_t))
            self._clk_t, self._clk_step, self._clk_up = t_host_s, None, ()
            return
        if excess - before[0] >= M / 2 and self._clk_step is None:   # a step up since the previous look
            self._clk_step = (*before, t_host_s)
        if self._clk_step is None:                # behind by creeping up (a slow device), not by a step
            return
        up = self._clk_up = tuple(x for x in (*self._clk_up, (t_host_s, excess))
                                  if x[0] >= t_host_s - CLOCK_CONFIRM_S)   # the looks of the last CLOCK_CONFIRM_S
        lows = [e for _, e in up]
        e0, t0_s, t_step = self._clk_step
        if t_host_s - t_step >= CLOCK_CONFIRM_S and len(up) >= CLOCK_CONFIRM_N and max(lows) - min(lows) < M / 2:
            wraps = int((min(lows) - e0) / M + 0.5)
            self._wraps = (wraps, t0_s) if wraps > 0 else None
            self._clk_step, self._clk_up = None, ()

    # -- rules 1 and 2 ---------------------------------------------------------------------
    def _missing_before_first(self, seq0: int, skipped0: int, frame_bytes: int) -> tuple[int, int]:
        """(samples lost before the first frame of a push, index into WHY)."""
        M = self.seq_modulus
        if not self._started:
            self._break_est = None
            return 0, SEQUENCE
        if self._break_est is not None:
            est = self._break_est
            self._break_est = None
            if M is None or seq0 < 0 or self._last_seq is None:
                return int(round(est)), REOPENED
            base = (seq0 - self._last_seq - 1) % M  # missing = base + j*M for the j closest to est
            j = max(0, int(round((est - base) / M)))
            return base + j * M, REOPENED
        last = self._last_seq
        base0 = np.array([(seq0 - last - 1) % M]) if M is not None and seq0 >= 0 and last is not None else None
        M_counted = M if base0 is not None else None
        return int(lost_frames(base0, np.array([skipped0]), frame_bytes, M_counted)[0]), int(skipped0 > 0)

    def _plausible(self, frames: Frames, missing: np.ndarray, why: np.ndarray) -> list[tuple[int, int | None]]:
        """Keep the gaps of rules 1-2 within ``max_gap`` (in place): a gap beyond it, or one
        that would take the push's gaps beyond it, gets only what its skipped bytes say.
        Returns those frames with the counter value before each (for the events); the
        frames whose fate ``max_gap`` decided otherwise than the default limit would go to
        ``decisions``."""
        limit = self._default_gap if self.max_gap is None else int(self.max_gap)
        over = _beyond(missing, limit)
        differs = np.flatnonzero(over != _beyond(missing, self._default_gap)) if self.max_gap is not None else ()
        idx = np.flatnonzero(over)
        fb, seq = frames.frame_bytes, frames.seq
        by_bytes = np.rint(frames.skipped_bytes()[idx] / fb) if fb else np.zeros(len(idx))
        missing[idx], why[idx] = np.minimum(by_bytes, limit), IMPLAUSIBLE
        self.decisions += [Placed(int(i), int(missing[i]), int(why[i])) for i in differs]
        return [(i, self._last_seq if i == 0 else int(seq[i - 1])) for i in idx.tolist()]

    def push(self, frames: Frames, events: list[Event] | tuple = ()) -> Block:
        """Place ``frames`` on the grid; returns the block (possibly empty) with gap
        events plus the given ``events``."""
        n = len(frames)
        evs = list(events)
        self.decisions = []
        shape = (len(self.axes),) if self.axes else ()
        if n == 0:
            t = np.zeros(0)
            return Block(t, np.zeros((0, *shape)), np.zeros((0, *shape), bool),
                         {k: np.zeros(0) for k in self.aux_names}, tuple(evs), self.axes)
        seq, skipped = frames.seq, frames.skipped_bytes()
        missing = np.zeros(n, dtype=np.int64)
        why = (skipped > 0).astype(np.int64)
        outage = self._break_est is not None and self._started
        missing[0], why[0] = self._missing_before_first(int(seq[0]), int(skipped[0]), frames.frame_bytes)
        M = self.seq_modulus
        if n > 1:
            counted = M is not None and seq[0] >= 0
            base = (np.diff(seq) - 1) % M if counted else None
            missing[1:] = lost_frames(base, skipped[1:], frames.frame_bytes, M if counted else None)
        held = missing[0] if outage else 0                  # an outage's count is checked by mark_break
        missing[0] -= held
        implausible = self._plausible(frames, missing, why)
        missing[0] += held
        notes = self._clock_wraps(missing, why) if self._started else {}
        self._wraps = None
        while self._placed and self._placed[0].frame < self._frames_in + n:   # what a live run's clock decided
            p, self._placed = self._placed[0], self._placed[1:]
            i = max(p.frame - self._frames_in, 0)
            missing[i], why[i] = p.missing, p.rule
            implausible = [x for x in implausible if x[0] != i]
            if p.rule == IMPLAUSIBLE:
                implausible.append((i, self._last_seq if i == 0 else int(seq[i - 1])))
            if p.wraps and "clock_wraps" in self.counters:
                self.counters["clock_wraps"] += p.wraps
        self.counters["implausible_gaps"] += len(implausible)
        self._frames_in += n
        self._started = True
        self._last_seq = int(seq[-1]) if seq[-1] >= 0 else None
        return self._assemble(frames, missing, why, evs, implausible, notes)

    def _clock_wraps(self, missing: np.ndarray, why: np.ndarray) -> dict[int, str]:
        """The whole wraps the host clock found (``observe_clock``), placed before the first
        frame (in place); the note for its gap event."""
        if self._wraps is None:
            return {}
        wraps, since_s = self._wraps
        M = int(self.seq_modulus or 0)
        missing[0] += wraps * M
        why[0] = HOST_CLOCK
        self.counters["clock_wraps"] += wraps
        self.decisions.insert(0, Placed(0, int(missing[0]), HOST_CLOCK, wraps))
        return {0: (f": {wraps} whole counter wrap(s) more than the counter and the bytes tell, lost after "
                    f"t={since_s:.3f} s; the samples since then sit up to {wraps * M / self.sample_rate_hz:g} s early")}

    def _assemble(self, frames: Frames, missing: np.ndarray, why: np.ndarray, evs: list[Event],
                  implausible: list[tuple[int, int | None]], notes: dict[int, str]) -> Block:
        """The block of ``frames`` with ``missing`` placeholders before each, its events and
        counters."""
        n = len(frames)
        shape = (len(self.axes),) if self.axes else ()
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
        for i, prev in implausible[:MAX_GAP_EVENTS]:
            ti = float(t[offs[i]])
            evs.append(Event(ti, "implausible", f"the sequence counter went from {prev} to {int(frames.seq[i])} at "
                                                f"t={ti:.6f} s: more than the samples that can be lost there; taken "
                                                f"as a counter reset, not as samples lost"))
        for g in gaps[:MAX_GAP_EVENTS]:
            tg = float(t[offs[g] - missing[g]])
            evs.append(Event(tg, "gap", f"{int(missing[g])} sample(s) lost at t={tg:.6f} s "
                                        f"({WHY[why[g]]}{notes.get(int(g), '')})"))
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
