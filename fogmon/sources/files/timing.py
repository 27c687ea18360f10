"""Time from time stamps: the sample grid of a series of logged samples, what their steps
say about the logging (jitter, bursts, gaps, alternating steps) and the block-mean
resampling of an irregular series (docs/readers.md, "What every reader does with time").

A logged sample carries the time it was stamped: its true sample time plus a delay
(transport, buffering) that is never negative and varies (jitter). The grid is found in
three steps:

1. the period P: the median step of the stamps (robust to gaps and to jitter);
2. the grid index of each sample: consecutive samples are consecutive grid points
   unless the stamps say samples are missing. The lag of sample k, (t_k - t_0) / P - k,
   grows by m where m samples are missing and stays grown; a delayed sample raises it
   only until the next ones catch up (a buffered burst: a long step, then short ones).
   So the lag is taken as its minimum over the sample and the ``LOOKAHEAD - 1`` samples
   after it, and each rise of that minimum, rounded to whole periods, is a gap (step by
   step, so that a clock slightly off P never adds up to a false gap). Where the rises
   are often a fraction of a period (a device or logger that stretches a step now and
   then without losing a sample: ``STRETCH_FRACTION``), only their whole periods count.
   With a rolling counter of modulus M the count is the one closest to that which the
   counter allows (d - 1 + j M).
3. the rate: 1 / the least-squares slope of the stamps over their grid indices (a gap
   that is not a whole number of periods, a device restarting at another phase, moves
   one segment, not the slope), and steps 2-3 once more with that period. A sample
   stamped more than half a period after the floor of its neighbours' lags (a delayed
   one: a buffered burst, an early flush before a slow topic's first regular sample)
   says when it was logged, not when it was sampled: it does not enter the slope.

Stamps that are not finite, repeated or going backwards are an error naming the sample
and the field; so are gaps beyond what the file can mean (the stamps spanning more than
``MAX_MISSING_RATIO`` times the samples present, or a rate beyond
``fogmon.formats.recording.MAX_SAMPLE_RATE_HZ``).

A series with many gaps or steps under half a period (more than
``IRREGULAR_GAP_FRACTION`` of its steps, and more than ``IRREGULAR_MIN``: a topic logged at alternating steps, a lossy
logger) leaves the Allan deviation few whole terms or no grid; so does one whose
stamps keep no one rate (``drift``: over some ``DRIFT_WINDOW`` samples the floor of
the lags moves by more than ``RATE_TOLERANCE`` of them, i.e. the local rate is more
than 1 % off the grid's, where a stated rate would be refused: a device clock that
wanders, a logger that drops samples in runs the grid cannot tell from jitter). Such a
series is refused with the resampling that fixes it (``resample_hz``): block means on
a coarser uniform grid (``block_means``), placed by the stamps themselves."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import minimum_filter1d

from fogmon.errors import FogmonError
from fogmon.formats.recording import MAX_MISSING_RATIO, MAX_SAMPLE_RATE_HZ

#: samples over which the lag's minimum is taken (a burst longer than this is a gap)
LOOKAHEAD = 32
#: stamps whose lag rises by a fraction of a period (0.25 to 0.75 off a whole number) at more
#: than this fraction of the steps do not sit on one grid: only whole periods count as gaps
STRETCH_FRACTION = 0.002
#: a series with more gaps and bursts than this fraction of its steps is irregular
IRREGULAR_GAP_FRACTION = 0.05
#: ... and more than this many of them (a short log with a few gaps is not irregular)
IRREGULAR_MIN = 10
#: a nominal rate (DBC cycle time, ``sample_rate_hz``) that differs from the stamps' by more
#: than this fraction is refused (unless forced)
RATE_TOLERANCE = 0.01
#: a nominal rate within this fraction of the stamps' is taken as it is (the stamps' own
#: resolution: a log stamped at exactly 100 Hz gives 100 Hz, not 99.99999999 Hz)
RATE_SNAP = 1e-5
#: samples over which the local rate is compared with the grid's (``drift``)
DRIFT_WINDOW = 256


@dataclass(frozen=True)
class Timing:
    """What the stamps of one series say: ``n`` samples over ``span_s`` (first to last
    stamp, s), ``median_step_s``, the grid rate ``rate_hz`` (grid periods / span),
    ``missing`` samples in ``gaps`` gaps, the longest gap ``max_run`` (samples),
    ``bursts`` (steps under half a period that the grid absorbed) and ``jitter_s`` (the
    stamps' spread about the grid: 1.4826 x the median absolute deviation, s)."""

    n: int
    span_s: float
    median_step_s: float
    rate_hz: float
    missing: int
    gaps: int
    max_run: int
    bursts: int
    jitter_s: float
    runs_p99: int = 0
    stretchy: bool = False
    drift: float = 0.0

    @property
    def drifting(self) -> bool:
        """The stamps keep no one rate: the lags' floor moves by more than RATE_TOLERANCE
        of the samples over some DRIFT_WINDOW of them (``drift``, periods per sample)."""
        return self.drift > RATE_TOLERANCE

    @property
    def mean_rate_hz(self) -> float:
        """Samples present per second: (n - 1) / span (Hz)."""
        return (self.n - 1) / self.span_s if self.span_s > 0 else math.nan

    @property
    def irregular(self) -> bool:
        """More gaps and bursts than IRREGULAR_GAP_FRACTION of the steps and IRREGULAR_MIN."""
        odd = self.gaps + self.bursts
        return self.drifting or (odd > IRREGULAR_MIN and odd > IRREGULAR_GAP_FRACTION * max(self.n - 1, 1))

    def resample_hint_hz(self) -> float:
        """A coarser rate whose blocks nearly all hold a sample whatever their phase and
        the jitter: the grid rate / (the 99th percentile of the gaps' lengths + 2)."""
        return self.rate_hz / (self.runs_p99 + 2)

    def describe(self) -> str:
        """One line: the mean rate, the grid and what is irregular."""
        parts = [f"{self.n} samples over {self.span_s:.6g} s = {self.mean_rate_hz:.6g} Hz mean",
                 f"grid {self.rate_hz:.6g} Hz (median step {self.median_step_s * 1e3:.6g} ms)"]
        if self.gaps:
            parts.append(f"{self.missing} missing in {self.gaps} gaps")
        if self.bursts:
            parts.append(f"{self.bursts} steps under half a period")
        if self.stretchy:
            parts.append("steps of a fraction of a period more (only whole periods counted as gaps)")
        if self.drifting:
            parts.append(f"the local rate {self.drift:.1%} off the grid's somewhere (over {DRIFT_WINDOW} samples)")
        return ", ".join(parts)


def _rises(t: np.ndarray, period: float) -> np.ndarray:
    """The rise of the lag's lookahead minimum before each sample after the first
    (periods; see the module docstring)."""
    lag = (t - t[0]) / period - np.arange(len(t))
    low = minimum_filter1d(lag, LOOKAHEAD, mode="constant", cval=np.inf, origin=-(LOOKAHEAD // 2))
    return np.maximum(np.diff(low), 0.0)


def _gaps(rise: np.ndarray, stretchy: bool, seq: np.ndarray | None, modulus: int | None) -> np.ndarray:
    """Samples missing before each sample (0 for the first): each rise rounded, or with
    ``stretchy`` stamps only its whole periods; with a counter, the count the counter
    allows closest to that."""
    est = np.floor(rise) if stretchy else np.rint(rise)
    if seq is None or modulus is None:
        m = est
    else:
        base = (np.diff(seq) - 1) % modulus
        m = base + np.maximum(0, np.rint((est - base) / modulus)) * modulus
    return np.concatenate(([0], m)).astype(np.int64)


def _slope(idx: np.ndarray, t: np.ndarray) -> float:
    """The least-squares slope of ``t`` over ``idx`` (s per grid period)."""
    k = idx - idx.mean()
    return float(np.dot(k, t - t.mean()) / np.dot(k, k))


def _floor(res: np.ndarray) -> np.ndarray:
    """The floor of the lags ``res`` (periods): their minimum over each sample and the
    LOOKAHEAD - 1 after it (the stamps' least delay there)."""
    return minimum_filter1d(res, LOOKAHEAD, mode="nearest", origin=-(LOOKAHEAD // 2))


def _grid_slope(idx: np.ndarray, t: np.ndarray, period: float) -> float:
    """The stamps' period (s): the least-squares slope of ``t`` over ``idx`` without the
    delayed samples (more than half a period above the floor of the lags about the
    ``period``'s grid), unless fewer than two are left."""
    res = (t - t[0]) / period - idx
    on = res - _floor(res) <= 0.5
    return _slope(idx[on], t[on]) if np.count_nonzero(on) >= 2 else _slope(idx, t)


def _drift(idx: np.ndarray, t: np.ndarray, period: float) -> float:
    """The largest move of the lags' floor over DRIFT_WINDOW samples (or the series, if
    shorter), per sample (periods per sample): 0 where the stamps keep the grid's rate."""
    w = min(DRIFT_WINDOW, len(t) - 1)
    if w < 1:
        return 0.0
    low = _floor((t - t[0]) / period - idx)
    return float(np.max(np.abs(low[w:] - low[:-w]))) / w


def grid_index(t_s, where: str, time_field: str, seq=None, modulus: int | None = None,
               ) -> tuple[np.ndarray, Timing]:
    """(grid index of every sample, Timing) from time stamps ``t_s`` (s, in file order),
    as the module docstring describes; ``seq`` (rolling counter, modulus ``modulus``)
    refines the gaps. ``where`` (file, topic) and ``time_field`` name the data in
    errors."""
    t = np.asarray(t_s, dtype=np.float64)
    if len(t) < 2:
        raise FogmonError(f"{where}: {len(t)} sample(s): too few to know the sample rate")
    if not np.all(np.isfinite(t)):
        i = int(np.argmax(~np.isfinite(t)))
        raise FogmonError(f"{where}: sample {i}, field {time_field}: time stamp is {float(t[i])!r}")
    step = np.diff(t)
    if step.min() <= 0:
        i = int(np.argmin(step)) + 1
        raise FogmonError(f"{where}: sample {i}, field {time_field}: time stamp {float(t[i])!r} s is "
                          f"{float(step[i - 1]):+.3g} s after the previous one: repeated or backward time stamps")
    span = float(t[-1] - t[0])
    med = float(np.median(step))
    if 1.0 / med > MAX_SAMPLE_RATE_HZ:
        raise FogmonError(f"{where}: field {time_field}: median step {med:.3g} s = {1 / med:.3g} Hz, beyond "
                          f"{MAX_SAMPLE_RATE_HZ:g} Hz: not the time stamps of a gyro")
    if span / med > MAX_MISSING_RATIO * len(t):
        i = int(np.argmax(step)) + 1
        raise FogmonError(f"{where}: sample {i}, field {time_field}: a jump of {float(step[i - 1]):.6g} s "
                          f"(median step {med:.6g} s) leaves {span / med:.3g} periods for {len(t)} samples: "
                          f"a corrupt time stamp or not one recording")
    seq_a = None if seq is None else np.asarray(seq, dtype=np.int64)
    rise = _rises(t, med)
    off = np.abs(rise - np.rint(rise))
    stretchy = bool(np.count_nonzero((rise > 0.25) & (off > 0.25)) > STRETCH_FRACTION * len(rise))
    period = med
    for _ in range(2):
        gaps = _gaps(_rises(t, period), stretchy, seq_a, modulus)
        idx = np.arange(len(t)) + np.cumsum(gaps)
        period = _grid_slope(idx, t, period)
    missing_runs = gaps[gaps > 0]
    res = (t - t[0]) / period - idx
    timing = Timing(n=len(t), span_s=span, median_step_s=med, rate_hz=1.0 / period,
                    missing=int(gaps.sum()), gaps=len(missing_runs),
                    max_run=int(missing_runs.max()) if len(missing_runs) else 0,
                    bursts=int(np.count_nonzero(step < 0.5 * period)),
                    jitter_s=float(1.4826 * np.median(np.abs(np.diff(res) - np.median(np.diff(res)))) * period),
                    runs_p99=int(np.percentile(missing_runs, 99)) if len(missing_runs) else 0,
                    stretchy=bool(stretchy), drift=_drift(idx, t, period))
    return idx, timing


def check_nominal(timing: Timing, nominal_hz: float | None, what: str, where: str, force: bool) -> float:
    """The sample rate to use (Hz): the stamps' ``timing.rate_hz``, or ``nominal_hz``
    (``what`` names where it came from: "`sample_rate_hz`", "the DBC cycle time ...")
    when it agrees within RATE_SNAP or when ``force``; a nominal rate off by more than
    RATE_TOLERANCE is a FogmonError with both numbers. Between the two: the stamps'."""
    measured = timing.rate_hz
    if nominal_hz is None:
        return measured
    off = nominal_hz / measured - 1.0
    if force or abs(off) <= RATE_SNAP:
        return float(nominal_hz)
    if abs(off) > RATE_TOLERANCE:
        raise FogmonError(f"{where}: {what} says {nominal_hz:.6g} Hz but the time stamps say {measured:.6g} Hz "
                          f"({timing.describe()}), {off:+.1%}: every tau would be off by that; leave it out to use "
                          f"the stamps, or give `force_rate` to use {nominal_hz:.6g} Hz anyway")
    return measured


def block_means(t_s: np.ndarray, values: np.ndarray, resample_hz: float, where: str
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block means on the uniform grid ``t_0 + j / resample_hz`` (s, Hz): block j holds
    the samples stamped in [t_0 + j / F, t_0 + (j + 1) / F) and gets the mean of those of
    them that are finite (per column of a 2-D ``values``). Returns (``j``, ``means``,
    ``counts``): the blocks holding at least one stamp, their means (NaN where a column
    has no finite sample) and the samples averaged (per column)."""
    t = np.asarray(t_s, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if not (resample_hz > 0 and math.isfinite(resample_hz)) or resample_hz > MAX_SAMPLE_RATE_HZ:
        raise FogmonError(f"`resample_hz` must be > 0 and <= {MAX_SAMPLE_RATE_HZ:g}, got {resample_hz}")
    span = float(t[-1] - t[0]) if len(t) else 0.0
    if span * resample_hz > MAX_MISSING_RATIO * max(len(t), 1):
        raise FogmonError(f"{where}: `resample_hz` {resample_hz:g} Hz over {span:.6g} s is "
                          f"{span * resample_hz:.3g} blocks for {len(t)} samples: not coarser than the data")
    block = np.floor((t - t[0]) * resample_hz).astype(np.int64)
    j, first = np.unique(block, return_index=True)
    ok = np.isfinite(v)
    sums = np.add.reduceat(np.where(ok, v, 0.0), first, axis=0)
    counts = np.add.reduceat(ok.astype(np.int64), first, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    return j, means, counts
