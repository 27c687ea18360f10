"""Platform motion: stretches where the measured rate moves far beyond the sensor's noise
and nothing (no ``rot_dps`` reference) says why: a turntable, a vehicle, a person
handling the unit, the ground shaking. Noise coefficients fitted over such a stretch
describe the motion, not the gyro (a hand-turned FOG "identifies" R = 7e9 deg/h^2), so
explain and the live pipeline keep them out of their fits and say so.

The test, on blocks of ``block_samples(sample_rate_hz)`` samples: a block moves when its mean
rate departs from the local reference (a running median of block means over
``REFERENCE_S``) by more than both

- ``K_BLOCK`` x the scatter of a quiet block mean (so it is not chance): block to block,
  or about its reference where the rate wanders on its own (a rate random walk),
- ``K_SAMPLE`` x the noise of a single sample (so it is not a slow wander or a small
  sway that the noise analysis models itself: vibration lines, bias instability).

Both scales are estimated from the quiet part of the recording itself (low quantiles, so
motion over most of the record still leaves them right). Single-sample outliers (glitches)
are not motion: samples beyond ``K_OUTLIER`` sample-sigmas of their block's median are left
out of the block mean. A constant-rate plateau longer than half of ``REFERENCE_S`` cannot
be told from a bias change and is not flagged (the reference follows it).

Offline (``find_motion``) a second, sample-scale test finds bursts shorter than a block,
whose block mean averages out (a vehicle's 3 Hz sway, an earthquake's coda): most of
``BURST_N`` consecutive samples on one side of every nearby reference, beyond both
``K_OUTLIER`` sample sigmas and ``K_BLOCK`` x the quiet spread of a sample about its
block mean. One or two extreme samples stay outliers.
"""
from __future__ import annotations

import warnings
from bisect import bisect_left, insort
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from fogmon.block import Event
from fogmon.davar.kernels import heap_sort, median_of
from fogmon.jit import F2, F8, kernel

#: a block moves beyond K_BLOCK x the quiet scatter of block means ...
K_BLOCK = 8.0
#: ... and beyond K_SAMPLE x the noise of one sample (both must hold)
K_SAMPLE = 3.0
#: samples beyond this many sample-sigmas from their block median are outliers, not motion
K_OUTLIER = 10.0
#: the local reference: running median of block means over this long (s)
REFERENCE_S = 300.0
#: flagged blocks closer than this (s, or two blocks) form one span
MERGE_S = 10.0
#: the quiet scales are low quantiles over blocks (motion may cover most of a record)
QUIET_QUANTILE = 0.25
#: a burst: the median of this many consecutive samples beyond the burst limit, one side
BURST_N = 5
#: the live gate holds this long (s) at the start, then judges it all with scales from it
WARMUP_S = 30.0
#: ... and at least this many test blocks
MIN_WARMUP_BLOCKS = 16


@dataclass(frozen=True)
class MotionSpan:
    """A stretch of platform motion: recording time ``t_start_s`` .. ``t_end_s`` (s) and
    the largest departure of a block-mean rate, or of a burst's samples, from its
    reference, ``peak_dph`` (deg/h). ``level_change``: the live gate's span ended when the
    rate was found to hold a new level (a step of the rate, such as a bias change, that
    the causal gate can tell from motion only once it has held for REFERENCE_S / 2)."""
    t_start_s: float
    t_end_s: float
    peak_dph: float
    level_change: bool = False


def block_samples(sample_rate_hz: float) -> int:
    """Samples per test block: 0.25 s, at least 32 samples."""
    return max(32, int(round(0.25 * sample_rate_hz)))


#: the standard deviation of a normal variable's middle 80 % is this fraction of sigma
_TRIMMED_STD_80 = 0.6616


@kernel((F2,))
def _trimmed_sigma(x: np.ndarray) -> np.ndarray:
    """Per row of ``x`` (NaN = none): the standard deviation of its middle 80 % over that
    of a normal variable's, i.e. a robust sigma that, unlike a MAD, stays right for
    quantized values, where most of them tie (NaN for a row with no value). Plain loops
    (numba's np.sort and np.std cost seconds of compile): the std as numpy.std."""
    out = np.empty(x.shape[0])
    v = np.empty(x.shape[1])
    for i in range(x.shape[0]):
        n = 0
        for j in range(x.shape[1]):
            if np.isfinite(x[i, j]):
                v[n] = x[i, j]
                n += 1
        heap_sort(v, n)
        k = n // 10
        size = n - 2 * k
        out[i] = np.nan
        if size > 0:
            mean = 0.0
            for j in range(k, n - k):
                mean += v[j]
            mean = mean / size
            ssd = 0.0
            for j in range(k, n - k):
                ssd += (v[j] - mean) * (v[j] - mean)
            out[i] = (ssd / size) ** 0.5 / _TRIMMED_STD_80
    return out


def robust_sigma_of_diffs(y: np.ndarray) -> np.ndarray:
    """Per row of ``y`` (blocks x samples, NaN = none): sigma of one sample (deg/h) from
    the robust sigma of first differences (insensitive to a slow trend and to a few
    outliers; right for quantized rates too)."""
    return _trimmed_sigma(np.diff(np.asarray(y, dtype=np.float64), axis=1)) / np.sqrt(2.0)


@kernel((F2, F8))
def _block_means(y: np.ndarray, sigma_1: float) -> np.ndarray:
    """Robust mean rate (deg/h) of each row of ``y`` (blocks x samples, NaN = no sample):
    samples beyond K_OUTLIER x ``sigma_1`` from the block median are left out; a block in
    fast motion, where most samples are that far, keeps its median (NaN ``sigma_1``: the
    plain mean; a row with no sample: NaN)."""
    out = np.empty(y.shape[0])
    v = np.empty(y.shape[1])
    w = np.empty(y.shape[1])
    for i in range(y.shape[0]):
        n = 0
        for j in range(y.shape[1]):
            if np.isfinite(y[i, j]):
                v[n] = y[i, j]
                w[n] = y[i, j]
                n += 1
        med = median_of(w, n)
        total = 0.0
        kept = 0
        for j in range(n):
            if not abs(v[j] - med) > K_OUTLIER * sigma_1:
                total += v[j]
                kept += 1
        if kept >= y.shape[1] // 4:
            out[i] = total / kept if kept else np.nan
        else:
            out[i] = med
    return out


def _quiet_scatter(means: np.ndarray) -> float:
    """Quiet scatter of a block mean (deg/h), from a low quantile of the steps between
    consecutive block ``means`` (the noise of one sample is the same quantile of the
    per-block sample sigmas)."""
    return float(np.quantile(np.abs(np.diff(means)), QUIET_QUANTILE)) / 0.3186 / np.sqrt(2.0)


def _quiet_departure(dev: np.ndarray) -> float:
    """Quiet scatter (deg/h) of a block mean's departure from its reference: the same low
    quantile of the departures ``dev`` (NaN entries ignored; NaN without any)."""
    d = np.abs(dev[np.isfinite(dev)])
    return float(np.quantile(d, QUIET_QUANTILE)) / 0.3186 if len(d) else float("nan")


def _quiet_scale(means: np.ndarray, dev: np.ndarray, n_ref: int) -> tuple[float, float]:
    """(scale, wander), deg/h. ``scale``: what a block mean's departure from its reference
    is judged against, the larger of the block-to-block scatter s_block of quiet block
    ``means`` and the quiet scatter s_dev of their departures ``dev`` from their
    references (medians of ``n_ref`` block means). ``wander``: the part of s_dev that
    white noise does not explain (it departs by s_block^2 (1 + pi / (2 n_ref)), the
    reference's own noise included): where the rate wanders on its own (a rate random
    walk, a ramp the causal reference lags) a block departs from its reference by more
    than block-to-block steps suggest, and that wander is the sensor's noise, not
    motion."""
    s_block, s_dev = _quiet_scatter(means), _quiet_departure(dev)
    white = s_block * np.sqrt(1.0 + np.pi / (2.0 * max(n_ref, 1)))
    wander = float(np.sqrt(s_dev**2 - white**2)) if s_dev > white else 0.0
    return float(np.nanmax([s_block, s_dev])), wander


def _level(median: np.ndarray | float, ref: np.ndarray | float, allowance: float) -> np.ndarray:
    """A block's level (deg/h) for the burst test: its ``median``, as far from its
    reference ``ref`` as the rate's own wander takes it (``allowance``: K_BLOCK x the
    wander of ``_quiet_scale``). A burst shorter than half a block does not move the
    median; a rate that wanders on its own takes it along."""
    return np.asarray(ref + np.clip(np.asarray(median) - ref, -allowance, allowance))


def _departures(means: np.ndarray, h: int) -> np.ndarray:
    """Each block mean's departure (deg/h) from the median of the ``h`` block ``means``
    before it, as the live gate's reference; while fewer than ``h`` came before (a
    start-up shorter than the reference), of all of them from the 5th block on."""
    ref = _RunningMedian(h)
    out = np.full(len(means), np.nan)
    for i, x in enumerate(means.tolist()):
        if len(ref) >= min(h, 4):
            out[i] = x - ref.median()
        ref.push(x)
    return out


def _limit(sigma_1: float, s_block: float) -> float:
    """Departure (deg/h) beyond which a block mean moves; NaN when the noise is unknown
    or zero (a constant signal cannot be judged)."""
    limit = max(K_BLOCK * s_block, K_SAMPLE * sigma_1)
    return limit if np.isfinite(limit) and limit > 0 else float("nan")


def _blocks(rate_dph: np.ndarray, valid: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(samples as blocks x m with NaN where invalid, whether each block has enough samples,
    each block's sample sigma in deg/h)."""
    y = np.where(valid, rate_dph, np.nan).reshape(-1, m).astype(np.float64)
    enough = np.sum(np.isfinite(y), axis=1) >= m // 2
    return y, enough, robust_sigma_of_diffs(y)


def find_motion(t_s: np.ndarray, rate_dph: np.ndarray, valid: np.ndarray, sample_rate_hz: float) -> list[MotionSpan]:
    """The platform-motion spans of a recording on a uniform grid (``t_s`` in s,
    ``rate_dph`` in deg/h with the reference rotation already removed, ``valid`` False
    where there is no sample), in time order; empty for a stationary recording. The
    reference of each block is centred on it (see ``MotionTracker`` for the causal one)."""
    from scipy.ndimage import median_filter  # offline only: the live gate's start-up does without it

    m = block_samples(sample_rate_hz)
    nb = len(rate_dph) // m
    y, enough, sig = _blocks(rate_dph[:nb * m], np.asarray(valid)[:nb * m], m)
    idx = np.flatnonzero(enough)
    if len(idx) < 4:
        return []
    sigma_1 = float(np.quantile(sig[idx], QUIET_QUANTILE))
    mu = _block_means(y[idx], sigma_1)
    n_ref = _reference_blocks(sample_rate_hz)
    ref = median_filter(mu, size=n_ref, mode="mirror")   # the first block is judged too
    dev = np.abs(mu - ref)
    h = n_ref // 2 + 1                          # the scale: departures as the live gate's
    scale, wander = _quiet_scale(mu, _departures(mu, h), h)
    limit = _limit(sigma_1, scale)
    if not np.isfinite(limit):
        return []
    moved = np.zeros(nb)
    moved[idx] = np.where(dev > limit, dev, 0.0)
    peak = np.repeat(moved, m)              # per sample: the departure that flagged it
    ref_all = np.full(nb, np.nan)
    ref_all[idx] = ref
    spread = float(np.quantile(_spreads(y[idx], mu), QUIET_QUANTILE))
    burst = _burst_departure(y, ref_all, K_BLOCK * wander, _burst_limit(sigma_1, spread))
    peak = np.where(peak > 0, peak, burst)       # a burst's samples, where no block mean moved
    dt, t0 = 1.0 / sample_rate_hz, float(t_s[0])
    out = []
    # one block of margin each side (onsets begin inside the neighbours); flagged samples
    # closer than the merge gap form one span
    for a, b in _runs(np.flatnonzero(peak > 0), _merge_blocks(sample_rate_hz) * m):
        a, b = max(0, a - m), min(nb * m - 1, b + m)
        out.append(MotionSpan(t0 + a * dt, min(t0 + b * dt, float(t_s[-1])), float(peak[a:b + 1].max())))
    return out


def _burst_departure(y: np.ndarray, ref: np.ndarray, allowance: float, limit: float) -> np.ndarray:
    """Per sample of ``y`` (blocks x samples, deg/h; ``ref`` each block's reference, NaN
    = none): the median departure (deg/h) of the BURST_N samples centred on it from the
    nearest of the references of its block and the two beside it and its block's level
    (``_level``), where that median departure is beyond ``limit`` on one side of all four
    (more than half of them depart: a burst), else 0. One or two extreme samples never
    make a burst; taking the nearest level keeps a level change inside a block (a bias
    step) from looking like one, and a rate that wanders on its own (a rate random walk)
    too."""
    from scipy.ndimage import median_filter

    if not np.isfinite(limit) or limit <= 0:
        return np.zeros(y.size)
    with warnings.catch_warnings():          # blocks with no reference (gaps): never a burst
        warnings.simplefilter("ignore", RuntimeWarning)
        near = np.stack([ref, np.r_[ref[:1], ref[:-1]], np.r_[ref[1:], ref[-1:]],
                         _level(np.nanmedian(y, axis=1), ref, allowance)])
        hi, lo = np.nanmax(near, axis=0), np.nanmin(near, axis=0)
    x = y.ravel()
    out = np.zeros(x.size)
    for d in (x - np.repeat(hi, y.shape[1]), np.repeat(lo, y.shape[1]) - x):
        med = median_filter(np.nan_to_num(d, nan=0.0), size=BURST_N, mode="nearest")
        out = np.where(med > limit, med, out)
    return out


def _spreads(y: np.ndarray, means: np.ndarray) -> np.ndarray:
    """Each block's robust spread of a sample about its block mean (deg/h; blocks x
    samples ``y``, NaN = none)."""
    return _trimmed_sigma(y - means[:, None]) if len(means) else np.empty(0)


def _peaks(y: np.ndarray, means: np.ndarray) -> np.ndarray:
    """Each block's largest departure of a sample from its block mean (deg/h; 0 for a
    block without samples): a burst needs more than the burst limit less the mean's own
    departure (the live gate's cheap pre-test)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nan_to_num(np.nanmax(np.abs(y - means[:, None]), axis=1), nan=0.0) if len(means) else np.empty(0)


def _burst_limit(sigma_1: float, spread: float) -> float:
    """The departure (deg/h) of a burst's samples (``find_motion``, the live gate): beyond
    K_OUTLIER x the noise of one sample and K_BLOCK x the quiet spread of a sample about
    its block mean (a low-pass sensor's sample-to-sample differences understate its noise)."""
    return max(K_OUTLIER * sigma_1, K_BLOCK * spread)


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


def _reference_blocks(sample_rate_hz: float) -> int:
    """Blocks in the running-median reference (odd, at least 5)."""
    return max(5, int(REFERENCE_S * sample_rate_hz / block_samples(sample_rate_hz))) | 1


def _merge_blocks(sample_rate_hz: float) -> int:
    """Flagged blocks at most this many blocks apart belong to one span."""
    return max(2, int(np.ceil(MERGE_S * sample_rate_hz / block_samples(sample_rate_hz))))


def _runs(idx: np.ndarray, gap: int) -> list[tuple[int, int]]:
    """(first, last) of each run of sorted (block or sample) indices with steps of at most
    ``gap``."""
    if not len(idx):
        return []
    cut = np.flatnonzero(np.diff(idx) > gap)
    return list(zip(np.r_[idx[0], idx[cut + 1]].tolist(), np.r_[idx[cut], idx[-1]].tolist(), strict=True))


class _RunningMedian:
    """The median of the last ``n`` values pushed (finite floats): a FIFO beside a sorted
    copy, so a push costs a bisect and a short memmove and the median a lookup, where
    ``np.median`` of the window would sort it at every block."""

    def __init__(self, n: int) -> None:
        self.n = n
        self._fifo: deque[float] = deque()
        self._sorted: list[float] = []

    def __len__(self) -> int:
        return len(self._fifo)

    def push(self, x: float) -> None:
        if len(self._fifo) == self.n:
            del self._sorted[bisect_left(self._sorted, self._fifo.popleft())]
        self._fifo.append(x)
        insort(self._sorted, x)

    def reset(self, values: np.ndarray) -> None:
        """Hold ``values`` (oldest first) instead."""
        self._fifo.clear()
        self._sorted.clear()
        for x in values.tolist():
            self.push(x)

    def median(self) -> float:
        s, k = self._sorted, len(self._sorted)
        return s[k // 2] if k % 2 else (s[k // 2 - 1] + s[k // 2]) / 2


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
        ref = densest_level(means, _limit(sigma_1, _quiet_scatter(means)) / 2.0)
        devs = _departures(means, h)
        scale, wander = _quiet_scale(means, devs, h)
        return cls(idx, sig, means, _spreads(y[idx], means), _peaks(y[idx], means), sigma_1, wander,
                   _limit(sigma_1, scale), ref, devs)


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
            self._burst_limit = _burst_limit(start.sigma_1, float(np.quantile(start.spreads, QUIET_QUANTILE)))
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
                self._sigma_1 = float(np.quantile(self._sig.values(), QUIET_QUANTILE))
                self._burst_limit = _burst_limit(self._sigma_1, float(np.quantile(self._spreads.values(),
                                                                                 QUIET_QUANTILE)))
                if len(self._means) >= 4:
                    scale, self._wander = _quiet_scale(self._means.values(), self._devs.values(), self._ref.n)
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


def motion_mask(t_s: np.ndarray, spans: list[MotionSpan]) -> np.ndarray:
    """True for the samples at ``t_s`` (s) inside any of ``spans``."""
    mask = np.zeros(len(t_s), dtype=bool)
    for s in spans:
        mask |= (t_s >= s.t_start_s) & (t_s <= s.t_end_s)
    return mask
