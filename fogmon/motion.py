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

A second, sample-scale test finds bursts shorter than a block, whose block mean averages
out (a vehicle's 3 Hz sway, an earthquake's coda): most of ``BURST_N`` consecutive
samples on one side of every nearby reference and of the block's level, beyond both
``K_OUTLIER`` sample sigmas and ``K_BLOCK`` x the quiet spread of a sample about its
block mean. One or two extreme samples stay outliers.

This module holds the test's statistics and its offline form, ``find_motion`` (a
reference centred on each block, for whole recordings); ``fogmon.motion_gate`` the live
form, causal and bounded.
"""
from __future__ import annotations

import math
import warnings
from bisect import bisect_left, insort
from collections import deque
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

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
#: the quietest stretch: this many consecutive blocks, at least (and 1/32 of the blocks) ...
QUIET_STRETCH_BLOCKS = 4
#: ... whose block means step this many times less than the quantile's scale (and less than
#: chance allows a stationary rate's quietest stretch, STRETCH_ALPHA): the quantile read motion
#: (motion over most of the blocks), the scales come from the rest around it
C_STRETCH = 4.0
#: the chance, over all stretches of one check, that a stationary rate's quietest stretch fires it
STRETCH_ALPHA = 0.01


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
    d = np.abs(np.diff(means))
    d = d[np.isfinite(d)]                      # NaN: no step (between runs of rest blocks)
    return float(np.quantile(d, QUIET_QUANTILE)) / 0.3186 / np.sqrt(2.0) if len(d) else float("nan")


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


def _rest_blocks(means: np.ndarray, sig: np.ndarray, m: int, h: int) -> tuple[np.ndarray, np.ndarray] | None:
    """When motion covers most of the blocks the quiet scales are read from (their low
    quantiles read motion): (which blocks are at rest, each rest block's departure from
    the median of the ``h`` rest block means before it, NaN for the others); else None.
    For each stretch length L (QUIET_STRETCH_BLOCKS or 1/32 of the blocks, and 8, 16,
    32, 64 blocks), the quietest stretch of L consecutive block ``means`` (the smallest
    RMS of their steps) gives a scale s_q; what its samples' noise (``sig``, ``m``
    samples a block) predicts for a white sensor, w_q, bounds it from below. The rest
    is sought when the quantile's scale exceeds max(C_STRETCH, the chance ratio) x
    max(s_q, w_q) for some L (``_chance_ratio``, Bonferroni over the stretches and the
    lengths: a long quiet stretch is strong evidence at a small ratio, a short one needs a
    large ratio), from the longest such stretch outwards: a block is at rest when its
    mean is within K_BLOCK x C_STRETCH x max(s_q, w_q) (and K_SAMPLE sample sigmas) of
    the median of the rest block means before it (after it, for the blocks before the
    stretch)."""
    n = len(means)
    if not np.all(np.isfinite(means)):
        return None
    lengths = sorted({max(QUIET_STRETCH_BLOCKS, n // 32), 8, 16, 32, 64})
    lengths = [big_l for big_l in lengths if big_l < n]
    scale, found = _quiet_scatter(means), None
    for big_l in lengths:
        r = np.sqrt(np.convolve(np.diff(means) ** 2, np.ones(big_l - 1) / (big_l - 1), "valid") / 2.0)
        j = int(np.argmin(r))
        s_q = float(np.median(sig[j:j + big_l]))
        q = max(float(r[j]), s_q / np.sqrt(m))
        if scale > max(C_STRETCH, _chance_ratio(big_l - 1, len(lengths) * n / big_l)) * q:
            found = (j, big_l, s_q, q)
    if found is None:
        return None
    i, big_l, sig_q, quiet = found
    bound = C_STRETCH * quiet
    limit = max(K_BLOCK * bound, K_SAMPLE * sig_q)
    rest = np.zeros(n, dtype=bool)
    devs = np.full(n, np.nan)
    for order in (range(i, n), range(i - 1, -1, -1)):
        ref = _RunningMedian(h)
        if order.step < 0:
            ref.reset(means[i:i + big_l][::-1])
        for k in order:
            x = float(means[k])
            if len(ref) >= min(h, 4):
                dev = x - ref.median()
                if abs(dev) > limit:
                    continue
                devs[k] = dev
            rest[k] = True
            ref.push(x)
    # a block beside one that moves is margin (an onset begins inside it), and motion that
    # passes through the reference level is not rest: only blocks whose neighbours rest too
    rest[1:-1] &= rest[:-2] & rest[2:]
    devs[~rest] = np.nan
    return rest, devs


def _chance_ratio(k: int, stretches: float) -> float:
    """How many times below a stationary rate's step scale the RMS of k steps falls with
    probability STRETCH_ALPHA / ``stretches`` (Bonferroni over the roughly independent
    stretches searched): sqrt(k / x), x that chi-square(k) quantile from its lower tail,
    x = 2 (p Gamma(k / 2 + 1))^(2 / k) (the CDF's leading term) up to k = 10, Wilson-Hilferty's
    cube root above. The quietest of many stretches of a rate random walk (block means
    that step by themselves) is that quiet by chance (docs/motion.md has what the rule did
    without this bound)."""
    p = STRETCH_ALPHA / max(stretches, 1.0)
    if k <= 10:
        x = 2.0 * math.exp((math.log(p) + math.lgamma(k / 2.0 + 1.0)) * 2.0 / k)
    else:                                   # Wilson-Hilferty
        x = k * max(1.0 - 2.0 / (9.0 * k) + NormalDist().inv_cdf(p) * math.sqrt(2.0 / (9.0 * k)), 1e-3) ** 3
    return math.sqrt(k / x)


def _rest_steps(means: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """The block means of the rest blocks, as pairs of neighbours (for ``_quiet_scatter``:
    a step is taken only between two neighbouring rest blocks): the means with NaN
    between runs."""
    return np.where(rest, means, np.nan)


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
    spreads = _spreads(y[idx], mu)
    rest = _rest_blocks(mu, sig[idx], m, h)
    if rest is None:
        scale, wander = _quiet_scale(mu, _departures(mu, h), h)
    else:                                       # motion over most of the record: the rest's scales
        sigma_1 = float(np.quantile(sig[idx][rest[0]], QUIET_QUANTILE))
        scale, wander = _quiet_scale(_rest_steps(mu, rest[0]), rest[1], h)
        spreads = spreads[rest[0]]
    limit = _limit(sigma_1, scale)
    if not np.isfinite(limit):
        return []
    moved = np.zeros(nb)
    moved[idx] = np.where(dev > limit, dev, 0.0)
    peak = np.repeat(moved, m)              # per sample: the departure that flagged it
    ref_all = np.full(nb, np.nan)
    ref_all[idx] = ref
    spread = float(np.quantile(spreads, QUIET_QUANTILE))
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
        # "mirror" (d c b | a b c d): the record's first and last samples enter each window once, so an
        # extreme one at an end is one sample of five there too, never a burst ("nearest" repeated it)
        med = median_filter(np.nan_to_num(d, nan=0.0), size=BURST_N, mode="mirror")
        out = np.where(med > limit, med, out)
    return out


def _spreads(y: np.ndarray, means: np.ndarray) -> np.ndarray:
    """Each block's robust spread of a sample about its block mean (deg/h; blocks x
    samples ``y``, NaN = none)."""
    return _trimmed_sigma(y - means[:, None]) if len(means) else np.empty(0)


def _burst_limit(sigma_1: float, spread: float) -> float:
    """The departure (deg/h) of a burst's samples (``find_motion``, the live gate): beyond
    K_OUTLIER x the noise of one sample and K_BLOCK x the quiet spread of a sample about
    its block mean (a low-pass sensor's sample-to-sample differences understate its noise)."""
    return max(K_OUTLIER * sigma_1, K_BLOCK * spread)


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


def motion_mask(t_s: np.ndarray, spans: list[MotionSpan]) -> np.ndarray:
    """True for the samples at ``t_s`` (s) inside any of ``spans``."""
    mask = np.zeros(len(t_s), dtype=bool)
    for s in spans:
        mask |= (t_s >= s.t_start_s) & (t_s <= s.t_end_s)
    return mask
