"""The live form of the platform-motion test (``fogmon.motion``): ``MotionGate``, causal and
bounded, as `fogmon monitor` and `fogmon replay` run it, and ``gate_record``, its
decisions over a whole record. Its reference is the median of the non-moving block means
before each block; a block's samples are judged for a burst on their own (``_block_burst``).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from fogmon.block import Event
from fogmon.motion import (
    BURST_N,
    K_BLOCK,
    QUIET_QUANTILE,
    REFERENCE_S,
    MotionSpan,
    _block_means,
    _blocks,
    _burst_limit,
    _departures,
    _level,
    _limit,
    _merge_blocks,
    _quiet_scale,
    _reference_blocks,
    _rest_blocks,
    _rest_steps,
    _RunningMedian,
    _spreads,
    block_samples,
)

#: the live gate holds this long (s) at the start, then judges it all with scales from it
WARMUP_S = 30.0
#: ... and at least this many test blocks
MIN_WARMUP_BLOCKS = 16


def _peaks(y: np.ndarray, means: np.ndarray) -> np.ndarray:
    """Each block's largest departure of a sample from its block mean (deg/h; 0 for a
    block without samples): a burst needs more than the burst limit less the mean's own
    departure (the live gate's cheap pre-test)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nan_to_num(np.nanmax(np.abs(y - means[:, None]), axis=1), nan=0.0) if len(means) else np.empty(0)


def _block_burst(x: np.ndarray, ref: float, allowance: float, limit: float) -> float:
    """The live gate's burst test of one block's samples ``x`` (deg/h, NaN = none) against
    the nearer of its reference ``ref`` and its level (``_level``): the largest median
    departure of BURST_N consecutive samples on one side beyond ``limit`` (a burst: more
    than half of them depart), else 0. The rule of
    ``_burst_departure``, but only over windows inside the block: its edge padding
    ("nearest") would make a burst of an outlier pair at every block edge, where the
    offline test pads only the record's two ends."""
    if not (np.isfinite(limit) and limit > 0 and np.isfinite(ref)) or len(x) < BURST_N:
        return 0.0
    level = float(_level(np.nanmedian(x), ref, allowance))
    best = 0.0
    for side in (np.nan_to_num(x - max(ref, level), nan=0.0), np.nan_to_num(min(ref, level) - x, nan=0.0)):
        med = np.median(np.lib.stride_tricks.sliding_window_view(side, BURST_N), axis=1)
        top = float(med.max())
        if top > limit:
            best = max(best, top)
    return best


class _Window:
    """The last ``n`` floats appended, readable in order as one array without a copy: each
    value is stored twice, ``n`` apart, so the window is always a contiguous slice."""

    def __init__(self, n: int) -> None:
        self.n = n
        self._buf = np.empty(2 * n)
        self._next = 0      # slot of the next value
        self._count = 0

    def __len__(self) -> int:
        return self._count

    def append(self, x: float) -> None:
        i = self._next
        self._buf[i] = self._buf[i + self.n] = x
        self._next = i + 1 if i + 1 < self.n else 0
        if self._count < self.n:
            self._count += 1

    def values(self) -> np.ndarray:
        """The window, oldest first (a read-only view, valid until the next append)."""
        end = self._next + self.n
        view = self._buf[end - self._count:end]
        view.flags.writeable = False
        return view


class Released(NamedTuple):
    """What ``MotionGate`` releases: the samples' rate (deg/h) and valid flags, in order,
    platform motion made invalid; ``moved`` True where the gate made a valid sample
    invalid (``valid | moved`` is the input's validity); the ``platform_motion`` events."""

    rate_dph: np.ndarray
    valid: np.ndarray
    moved: np.ndarray
    events: list[Event]


def warmup_blocks(sample_rate_hz: float) -> int:
    """Test blocks the live gate holds before it judges any: WARMUP_S of them, at least
    MIN_WARMUP_BLOCKS."""
    return max(MIN_WARMUP_BLOCKS, int(np.ceil(WARMUP_S * sample_rate_hz / block_samples(sample_rate_hz))))


def densest_level(means: np.ndarray, half_width: float) -> float:
    """The level (deg/h) most block ``means`` agree on: the median of the largest set of
    them within +-``half_width`` of one of them. Quiet blocks agree to their scatter;
    a turn's blocks spread over its rates, so motion over most of a start-up still
    leaves its quiet level (NaN without means)."""
    s = np.sort(means[np.isfinite(means)])
    if not len(s):
        return float("nan")
    if not np.isfinite(half_width):
        return float(np.median(s))
    lo = np.searchsorted(s, s - half_width, side="left")
    hi = np.searchsorted(s, s + half_width, side="right")
    i = int(np.argmax(hi - lo))
    return float(np.median(s[lo[i]:hi[i]]))


@dataclass(frozen=True)
class _Startup:
    """The live gate's start-up judgement of its first blocks: the blocks with enough
    samples (``idx``), each block's sample sigma (``sig``) and the robust means of those
    (``means``), the quiet scales (``sigma_1``, ``wander``, ``limit``, deg/h) from them, their
    reference ``ref`` (deg/h): the level most of their means agree on (NaN with fewer
    than 4 blocks: nothing is judged), and each mean's departure from the median of the
    ``h`` before it (``devs``, deg/h; the scale's, as the running gate's)."""

    idx: np.ndarray
    sig: np.ndarray
    means: np.ndarray
    spreads: np.ndarray
    peaks: np.ndarray
    sigma_1: float
    wander: float
    limit: float
    ref: float
    devs: np.ndarray
    spread_q: float = float("nan")

    @classmethod
    def of(cls, rate_dph: np.ndarray, valid: np.ndarray, m: int, h: int) -> _Startup:
        y, enough, sig = _blocks(rate_dph, valid, m)
        idx = np.flatnonzero(enough)
        if len(idx) < 4:
            means = _block_means(y[idx], np.nan)
            return cls(idx, sig, means, _spreads(y[idx], means), _peaks(y[idx], means), float("nan"),
                       float("nan"), float("nan"), float("nan"), np.empty(0))
        sigma_1 = float(np.quantile(sig[idx], QUIET_QUANTILE))
        means = _block_means(y[idx], sigma_1 if sigma_1 > 0 else np.nan)
        spreads = _spreads(y[idx], means)
        devs = _departures(means, h)
        rest = _rest_blocks(means, sig[idx], m, h)
        if rest is None:
            scale, wander = _quiet_scale(means, devs, h)
            spread_q = float(np.quantile(spreads, QUIET_QUANTILE))
        else:                               # motion over most of the start-up: the rest's scales
            sigma_1 = float(np.quantile(sig[idx][rest[0]], QUIET_QUANTILE))
            devs = rest[1]
            scale, wander = _quiet_scale(_rest_steps(means, rest[0]), devs, h)
            spread_q = float(np.quantile(spreads[rest[0]], QUIET_QUANTILE))
        limit = _limit(sigma_1, scale)
        ref = densest_level(means if rest is None else means[rest[0]], limit / 2.0)
        return cls(idx, sig, means, spreads, _peaks(y[idx], means), sigma_1, wander,
                   limit, ref, devs, spread_q)


class MotionGate:
    """The live form of ``find_motion``: causal and bounded. ``push`` takes the analysed
    rate (deg/h) of each incoming block and returns (``Released``) the samples it has
    judged, in order, the moving ones (plus one block of margin each side) made invalid,
    and ``platform_motion`` events at the start and end of each span; ``flush``
    releases the rest at the end of a run.

    Start-up: the gate holds every sample until ``warmup_blocks`` test blocks with
    samples have come (WARMUP_S, at least MIN_WARMUP_BLOCKS; or the run ends), takes the
    quiet scales from them and, as their reference, the level most of their block
    means agree on (``densest_level``), and judges them all: motion from the first
    sample on is found, and nothing reaches the analysis unjudged. Then each test block
    is judged as it completes, held back by at most two blocks: its reference is the
    median of the non-moving block means of the last REFERENCE_S / 2; the quiet scales
    are low quantiles over the last ``HISTORY_S``, refreshed every ``RESCALE_BLOCKS``
    blocks or ``RESCALE_S``, whichever comes first (a 1 Hz gate's blocks are 32 s). A
    departure that holds as a steady level (every block mean of the last
    REFERENCE_S / 2 within the limit of their median) is a bias change, not motion: it
    becomes the reference. The decisions do not depend on how the samples are cut into
    pushes."""

    HISTORY_S = 3600.0
    RESCALE_BLOCKS = 64
    RESCALE_S = 300.0

    def __init__(self, sample_rate_hz: float) -> None:
        self.m = block_samples(sample_rate_hz)
        self.warmup = warmup_blocks(sample_rate_hz)
        self._rescale = min(self.RESCALE_BLOCKS, max(1, int(self.RESCALE_S * sample_rate_hz / self.m)))
        n_hist = max(self.warmup, int(self.HISTORY_S * sample_rate_hz / self.m))
        self._sig = _Window(n_hist)
        self._means = _Window(n_hist)
        self._devs = _Window(n_hist)       # departures of the non-moving block means (start-up: _departures)
        self._spreads = _Window(n_hist)
        n_ref = _reference_blocks(sample_rate_hz) // 2 + 1
        self._ref = _RunningMedian(n_ref)
        self._recent = _Window(n_ref)      # every block mean judged: a steady new level
        self._gap = _merge_blocks(sample_rate_hz)
        self._limit = float("nan")
        self._wander = 0.0                 # deg/h: the rate's own wander of a block's level (_quiet_scale)
        self._sigma_1 = float("nan")
        self._burst_limit = float("nan")
        self._n_judged = 0
        self._warm = False
        self._seen = 0                     # start-up: complete blocks looked at, of them with enough samples
        self._seen_enough = 0
        self._t = np.empty(0)
        self._y = np.empty(0)
        self._v = np.empty(0, dtype=bool)
        self._moved = np.empty(0, dtype=bool)
        self._judged = 0                   # samples at the buffer's start already judged
        self._span: list[float] | None = None      # open span: [t_start_s, t_end_s, peak_dph]
        self._stepped = False              # the open span's rate has settled at a new level
        self._quiet_blocks = 0             # non-moving blocks since the open span's last moving one
        self._mask_next = False            # the block after a span is margin
        self.spans: list[MotionSpan] = []  # closed spans, for the run's summary
        self.samples_excluded = 0

    def push(self, t_s: np.ndarray, rate_dph: np.ndarray, valid: np.ndarray) -> Released:
        """The samples released now (judged), and the events."""
        self._t = np.concatenate([self._t, t_s])
        self._y = np.concatenate([self._y, rate_dph])
        self._v = np.concatenate([self._v, valid])
        self._moved = np.concatenate([self._moved, np.zeros(len(t_s), dtype=bool)])
        events: list[Event] = []
        if not self._warm:
            n = self._warmup_samples()
            if not n:
                return self._take(0, events)
            events += self._start(n)
        events += self._judge_blocks()
        return self._take(max(0, self._judged - self.m), events)   # the last judged block stays: margin

    def flush(self) -> Released:
        """Everything still held (the last partial block is not judged; a run shorter
        than the start-up is judged as a whole), and the event closing a span still open."""
        events = [] if self._warm else self._start(len(self._y) // self.m * self.m)
        if self._span:
            events.append(self._close(float(self._t[-1]) if len(self._t) else self._span[1]))
        return self._take(len(self._y), events)

    def _take(self, n: int, events: list[Event]) -> Released:
        out = Released(self._y[:n], self._v[:n], self._moved[:n], events)
        self._t, self._y, self._v, self._moved = self._t[n:], self._y[n:], self._v[n:], self._moved[n:]
        self._judged = max(0, self._judged - n)
        return out

    def _warmup_samples(self) -> int:
        """Start-up: once the first ``warmup`` blocks with enough samples are held and the
        latest of them is at their reference level (motion under way goes on being held),
        the samples to judge at once; also after 4 x ``warmup`` blocks, whatever they
        hold. Else 0."""
        m = self.m
        for k in range(self._seen, len(self._v) // m):
            self._seen = k + 1
            enough = np.count_nonzero(self._v[k * m:(k + 1) * m]) >= m // 2
            self._seen_enough += int(enough)
            if self._seen >= 4 * self.warmup:
                return self._seen * m
            if enough and self._seen_enough >= self.warmup:
                start = _Startup.of(self._y[:self._seen * m], self._v[:self._seen * m], m, self._ref.n)
                if not abs(start.means[-1] - start.ref) > start.limit:   # NaN: cannot judge, start
                    return self._seen * m
        return 0

    def _start(self, n: int) -> list[Event]:
        """Judge the first ``n`` samples (whole blocks) at once (``_Startup``)."""
        self._warm = True
        if n < self.m:
            return []
        start = _Startup.of(self._y[:n], self._v[:n], self.m, self._ref.n)
        self._sigma_1, self._wander, self._limit = start.sigma_1, start.wander, start.limit
        if len(start.idx) >= 4:
            self._burst_limit = _burst_limit(start.sigma_1, start.spread_q)
        events: list[Event] = []
        for k, mean, spread, peak in zip(start.idx, start.means, start.spreads, start.peaks, strict=True):
            events += self._judge(int(k) * self.m, float(start.sig[k]), float(mean), float(spread), float(peak),
                                  start.ref)
        self._n_judged = len(start.idx)
        self._devs = _Window(self._devs.n)            # the scale's departures: from the h blocks before
        for d in start.devs[np.isfinite(start.devs)].tolist():
            self._devs.append(d)
        self._judged = n
        return events

    def _judge_blocks(self) -> list[Event]:
        """Judge the complete blocks not judged yet, in order, each against the running
        reference; the scales refreshed every RESCALE_BLOCKS blocks or RESCALE_S (a block's robust mean
        uses the sample noise known before it)."""
        m, a = self.m, self._judged
        nb = (len(self._y) - a) // m
        if not nb:
            return []
        y, enough, sig = _blocks(self._y[a:a + nb * m], self._v[a:a + nb * m], m)
        events: list[Event] = []
        means, spreads, peaks, first, sigma = np.empty(0), np.empty(0), np.empty(0), 0, float("nan")
        for k in np.flatnonzero(enough).tolist():
            if k - first >= len(means) or not _same(sigma, self._sigma_1):
                sigma, first = self._sigma_1, k
                means = _block_means(y[k:k + self.RESCALE_BLOCKS], sigma if sigma > 0 else np.nan)
                spreads = _spreads(y[k:k + self.RESCALE_BLOCKS], means)
                peaks = _peaks(y[k:k + self.RESCALE_BLOCKS], means)
            ref = self._ref.median() if len(self._ref) else float("nan")
            events += self._judge(a + k * m, float(sig[k]), float(means[k - first]), float(spreads[k - first]),
                                  float(peaks[k - first]), ref)
            self._n_judged += 1
            if self._n_judged % self._rescale == 0:
                means_h, sig_h, spreads_h = self._means.values(), self._sig.values(), self._spreads.values()
                rest = _rest_blocks(means_h, sig_h, m, self._ref.n) if len(means_h) >= 4 else None
                if rest is not None:          # motion over most of the history: the rest's scales
                    sig_h, spreads_h = sig_h[rest[0]], spreads_h[rest[0]]
                self._sigma_1 = float(np.quantile(sig_h, QUIET_QUANTILE))
                self._burst_limit = _burst_limit(self._sigma_1, float(np.quantile(spreads_h, QUIET_QUANTILE)))
                if len(self._means) >= 4:
                    scale, self._wander = (_quiet_scale(means_h, self._devs.values(), self._ref.n) if rest is None
                                           else _quiet_scale(_rest_steps(means_h, rest[0]), rest[1], self._ref.n))
                    self._limit = _limit(self._sigma_1, scale)
        self._judged = a + nb * m
        return events

    def _judge(self, a: int, sig: float, mean: float, spread: float, peak: float, ref: float) -> list[Event]:
        """Judge the block of samples a .. a+m of the buffer (sample sigma ``sig``, robust
        mean ``mean``, spread about it ``spread``, largest departure of a sample from it
        ``peak`` and reference ``ref``, deg/h; NaN: none): it moves when its mean departs
        beyond the limit or its samples hold a burst (``_block_burst``); the block before
        it is still held."""
        m = self.m
        t0, t1 = float(self._t[a]), float(self._t[a + m - 1])
        self._sig.append(sig)
        self._means.append(mean)
        self._spreads.append(spread)
        self._recent.append(mean)
        dev = abs(mean - ref)
        moving = bool(dev > self._limit)              # NaN limit or reference: never
        in_burst = False
        if moving and self._steady():                 # a bias change: the new level is the reference
            self._ref.reset(self._recent.values())
            moving = False
            self._stepped = self._span is not None
        elif not moving and peak + dev > self._burst_limit:   # a burst its mean averages out (a turn at 10 Hz)
            burst = _block_burst(np.where(self._v[a:a + m], self._y[a:a + m], np.nan), ref,
                                 K_BLOCK * self._wander, self._burst_limit)
            if burst > 0:
                dev, moving, in_burst = burst, True, True
        if not moving:
            self._devs.append(dev)                    # the quiet departures, for the scale
        out: list[Event] = []
        if moving:
            self._mask(max(0, a - m), a + m)            # this block and the one before it
            if self._span is None:
                self._span = [float(self._t[max(0, a - m)]), t1, dev]
                what = (f"a burst of samples leaves the block's level by {dev:.4g} deg/h (burst limit "
                        f"{self._burst_limit:.3g} deg/h)" if in_burst else
                        f"the rate leaves its reference by {dev:.4g} deg/h (limit {self._limit:.3g} deg/h)")
                out.append(Event(t0, "platform_motion", f"platform motion: {what}; kept out of the noise analysis"))
            else:
                self._span[1], self._span[2] = t1, max(self._span[2], dev)
            self._quiet_blocks, self._mask_next = 0, True
        else:
            self._ref.push(mean)
            if self._mask_next:
                assert self._span is not None, "_mask_next is set only while a span is open"
                self._mask(a, a + m)
                self._span[1] = t1
                self._mask_next = False
            if self._span is not None:
                self._quiet_blocks += 1
                if self._quiet_blocks > self._gap:
                    out.append(self._close(t1))
        return out

    def _steady(self) -> bool:
        """Every block mean of the last REFERENCE_S / 2 lies within the limit of their
        median: a level that holds, not motion."""
        if len(self._recent) < self._recent.n:
            return False
        r = self._recent.values()
        return bool(np.max(np.abs(r - np.median(r))) <= self._limit)

    def _mask(self, a: int, b: int) -> None:
        hit = self._v[a:b]
        self.samples_excluded += int(np.count_nonzero(hit))
        self._moved[a:b] |= hit
        self._v[a:b] = False

    def _close(self, t_s: float) -> Event:
        assert self._span is not None, "called with a span open"
        a, b, peak = self._span
        self.spans.append(MotionSpan(a, b, peak, self._stepped))
        self._span, stepped, self._stepped = None, self._stepped, False
        if stepped:
            return Event(t_s, "platform_motion", f"platform motion ended: {a:.3f} .. {b:.3f} s, peak {peak:.4g} deg/h "
                         f"from the reference; the rate has held a new level since: a step (a bias change), not "
                         f"necessarily motion, kept out until it had held for {REFERENCE_S / 2:g} s")
        return Event(t_s, "platform_motion", f"platform motion ended: {a:.3f} .. {b:.3f} s, "
                     f"peak {peak:.4g} deg/h from the reference")


def _same(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same float (NaN equals NaN)."""
    return a == b or (a != a and b != b)


@dataclass(frozen=True)
class GatedRecord:
    """``MotionGate`` over a whole record: ``valid`` with platform motion made invalid,
    the ``spans`` (s from the first sample) and the valid samples kept out."""

    valid: np.ndarray
    spans: list[MotionSpan]
    samples_excluded: int


def gate_record(rate_dph: np.ndarray, sample_rate_hz: float, valid: np.ndarray | None = None) -> GatedRecord:
    """The live gate's decisions over a whole record (``rate_dph`` in deg/h, NaN or
    ``valid`` False: no sample): the same as `fogmon replay` makes on it, however the
    replay cuts it into blocks."""
    y = np.asarray(rate_dph, dtype=np.float64)
    ok = np.isfinite(y) if valid is None else np.asarray(valid, dtype=bool) & np.isfinite(y)
    gate = MotionGate(sample_rate_hz)
    first = gate.push(np.arange(len(y)) / sample_rate_hz, y, ok)
    rest = gate.flush()
    return GatedRecord(np.concatenate([first.valid, rest.valid]), list(gate.spans), gate.samples_excluded)
