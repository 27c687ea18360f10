"""Streaming dynamic Allan deviation, rate in deg/h: O(M) work per sample for M taus,
whatever the window length, and no per-window recomputation.

Terms of factor m come from prefix sums of (rate - reference level) in a linear buffer of
``window + reanchor`` samples; when it is full the last window moves to the front and is
re-referenced to its median, so an hours-long bias never costs precision. No single
sample changes a window that does not hold it: a huge one (|rate| > 1e8 deg/h or
infinite) enters no sum and makes the terms spanning it +inf, a large one (more than
65,536 deg/h from the reference level) stays out of the main prefix sums (see
fogmon/davar/kernels.py). Two modes:

- recorded sums (hop >= RECORD_MIN_HOP, the usual case): per m only the term ending at
  each new sample is computed and added to a cumulative sum; the cumulative sum at each
  future window's first term is recorded (window / hop records per tau) and a window's
  sum is the cumulative sum at its last sample minus that record. Nothing ever leaves a
  sum, so nothing cancels: no drift and no recompute, over any run length. Re-anchoring
  re-bases the cumulative sums on their current value (the records follow).
- running sums (small hops, Galleani's fast DAVAR recursion): per m the window's sum; a
  new sample adds the term ending at it and removes the term starting at the sample that
  left. Re-anchoring recomputes every sum exactly, and a rounding bound forces exact
  recomputes before a cancellation (a huge glitch leaving) could cost precision.
"""
from __future__ import annotations

import numpy as np

from fogmon.block import Block
from fogmon.davar import kernels, running_sums
from fogmon.davar.batch import _prepare, _samples, edf_rows, statistics, window_edf
from fogmon.davar.result import CONFIDENCE, AdevResult, DadevResult, WindowSums
from fogmon.davar.taus import tau_grid

RECORD_MIN_HOP = 64  # samples; below it the window / hop records per tau would outgrow the buffer
STAGE = 256
"""Samples a push that completes no window may stage (copied, no engine call) before
they enter the engine: a one-sample push costs a few microseconds."""


class StreamingDadev:
    """Sliding-window overlapping ADEV of a rate stream sampled at ``sample_rate_hz`` (Hz) over
    windows of ``window_s`` (s), emitted every ``hop_s`` (s, default window_s / 4) once
    the first window is complete. ``alpha``: noise type per tau for the confidence
    bounds (Greenhall's EDF; default: the EDF of the noise mixture of a quick IEEE-952
    fit, refreshed at most every max(hop, window / 4) samples). ``reanchor``: samples between re-references (and,
    with running sums, exact recomputes; default max(4 x window, 4096)); plus at most
    one early re-reference per buffer fill when most samples since the last one are
    large (the reference level came from a glitch)."""

    def __init__(self, sample_rate_hz: float, window_s: float, taus="octave", hop_s: float | None = None,
                 confidence: float = CONFIDENCE, alpha=None, reanchor: int | None = None):
        self.sample_rate_hz = float(sample_rate_hz)
        self.window_n = _samples(window_s, sample_rate_hz, "window_s")
        self.hop_n = _samples(window_s / 4.0 if hop_s is None else hop_s, sample_rate_hz, "hop_s")
        self.m = tau_grid(sample_rate_hz, self.window_n, taus)
        self.confidence = confidence
        self.alpha = None if alpha is None else np.broadcast_to(np.asarray(alpha, np.int64), self.m.shape)
        self.reanchor = int(reanchor) if reanchor is not None else max(4 * self.window_n, 4096)
        cap = self.window_n + self.reanchor
        self._y = np.zeros(cap)
        self._v = np.zeros(cap, dtype=np.bool_)
        # prefix arrays (kernels' ``pre``): main sums, counts, large-sample side sums, huge counts
        self._pre = (np.zeros(cap + 1), np.zeros(cap + 1, dtype=np.int64), np.zeros(cap + 1), np.zeros(cap + 1),
                     np.zeros(cap + 1, dtype=np.int64))
        self._len = 0  # samples in the buffer
        self._base = 0  # absolute index of buffer position 0
        self._ref = 0.0  # reference level (deg/h) subtracted before the prefix sums
        self._ref_set = False
        self._since = 0  # samples appended since the last re-reference
        self._large = 0  # large samples among them (many: the reference level is off)
        self._early = False  # an early re-reference was done since the buffer was last full
        nm = len(self.m)
        # recorded sums: the cumulative sum of squared terms (s + c) and valid-term count (n)
        # per tau, and their records at the window starts to come; running sums: the window's
        self._recorded = self.hop_n >= RECORD_MIN_HOP
        self._s = np.zeros(nm)
        self._c = np.zeros(nm)
        self._n = np.zeros(nm, dtype=np.int64)
        self._h = np.zeros(nm, dtype=np.int64)  # recorded sums: segments holding a term spanning a huge sample
        ring = (self.window_n - 1) // self.hop_n + 2 if self._recorded else 0
        self._rec_s = np.zeros((nm, ring))
        self._rec_c = np.zeros((nm, ring))
        self._rec_n = np.zeros((nm, ring), dtype=np.int64)
        self._rec_h = np.zeros((nm, ring), dtype=np.int64)
        self._err = np.zeros(nm)  # bound of the rounding in (_s + _c), see running_sums.stream_update
        self._edf_prev = None  # EDF state of the windows emitted so far, see batch.edf_rows
        self._stage_y = np.empty(STAGE)  # samples pushed but not yet in the engine (see push)
        self._stage_v = np.ones(STAGE, dtype=np.bool_)
        self._staged = 0
        self._next_end = self.window_n - 1  # last sample of the next window to emit (absolute index)
        self._empty: DadevResult | None = None  # the zero-row result of a push that completes no window

    @property
    def n_pushed(self) -> int:
        """Samples pushed so far."""
        return self._base + self._len + self._staged

    def push(self, rate_dph, valid=None) -> DadevResult:
        """Feed samples: an array of rate in deg/h (``valid`` mask optional, NaN is
        invalid) or a :class:`fogmon.block.Block` (its ``valid`` flags). Returns the
        windows completed at hop boundaries inside this block (possibly zero rows; their
        adev formed when first read, see :class:`DadevResult`);
        ``end_index`` counts samples from the first push. A small array that completes
        no window is only staged (up to STAGE samples): same results, a few us per call."""
        if type(rate_dph) is np.ndarray and rate_dph.ndim == 1 and (
                valid is None or (type(valid) is np.ndarray and valid.shape == rate_dph.shape)):
            k, n = self._staged, rate_dph.shape[0]
            if k + n <= STAGE and self._base + self._len + k + n <= self._next_end:
                self._stage_y[k:k + n] = rate_dph
                self._stage_v[k:k + n] = True if valid is None else valid
                self._staged = k + n
                if self._empty is None:
                    self._empty = self._frames(np.zeros(0, np.int64), np.zeros((0, len(self.m))),
                                               np.zeros((0, len(self.m)), np.int64), 0)
                return self._empty
        w = self.window_n
        ends, sums, counts = self.advance(rate_dph, valid)
        gapless = None
        if self.alpha is None:
            gapless, self._edf_prev = edf_rows(sums, counts, ends, self.m, w, max(self.hop_n, w // 4), self._edf_prev)
        return self._frames(ends, sums, counts, self.alpha, gapless)

    def _frames(self, ends, sums, counts, alpha, gapless=None) -> DadevResult:
        """The windows ending at ``ends``: their EDF now (from the counts), their adev when
        first read (``WindowSums``: at hop 1 a push emits a window per sample, and most
        readers read a few)."""
        w = self.window_n
        edf = window_edf(counts, self.m, w, alpha, gapless)
        return DadevResult((ends - (w - 1) / 2.0) / self.sample_rate_hz, ends, self.m / self.sample_rate_hz, self.m,
                           WindowSums(sums, counts), edf, counts, self.sample_rate_hz,  # type: ignore[arg-type]
                           w / self.sample_rate_hz, self.hop_n / self.sample_rate_hz, self.confidence)

    def advance(self, rate_dph, valid=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The engine alone: feed samples like :meth:`push` and return, for the windows
        completed at hop boundaries, (end_index (T), sums of squared terms (deg/h)^2
        (T x M), valid-term counts (T x M; at hops below RECORD_MIN_HOP a read-only
        broadcast of one row when every window has the same)); Allan variance = sums /
        (2 counts)."""
        if isinstance(rate_dph, Block):
            rate_dph, valid = rate_dph.rate_dph, rate_dph.valid if valid is None else valid
        y, ok = _prepare(rate_dph, valid)
        if self._staged:  # staged samples first (they complete no window)
            sy, sv = _prepare(self._stage_y[:self._staged], self._stage_v[:self._staged])
            y, ok = np.concatenate([sy, y]), np.concatenate([sv, ok])
            self._staged = 0
        w, cap = self.window_n, len(self._y)
        a0 = self._base + self._len
        k0 = -(-(max(a0, w - 1) - (w - 1)) // self.hop_n)
        ends = np.arange(w - 1 + k0 * self.hop_n, a0 + len(y), self.hop_n, dtype=np.int64)
        # one block for both: freed together, the next call's block reuses the memory
        # instead of faulting pages in afresh (glibc returns separate large arrays to the OS)
        block = np.empty((2, len(ends), len(self.m)))
        sums, counts = block[0], block[1].view(np.int64)
        i = row = 0
        spans = []  # running sums: row spans whose counts are all in their first row (see running_sums.stream_update)
        while i < len(y):
            # re-anchor when the buffer is full, or once early when most samples since the
            # last re-reference are large (a reference level taken from a glitch)
            early = not self._early and 2 * self._large > self._since >= max(16, w // 8)
            if self._len == cap or early:
                self._early = early
                keep = min(self._len, w)
                self._ref = kernels.stream_reanchor(self._y, self._v, self._pre, self._len, keep, self.m,
                                                    self._s, self._c, self._n, self._err, self._recorded,
                                                    self._rec_s, self._rec_c, self._ref)
                self._base += self._len - keep
                self._len = keep
                self._since = self._large = 0
            take = min(len(y) - i, cap - self._len)
            yc, vc = y[i:i + take], ok[i:i + take]
            if not self._ref_set:
                ref = kernels.reference_level(yc, vc)
                if not np.isnan(ref):
                    self._ref, self._ref_set = ref, True
            self._large += kernels.stream_append(yc, vc, self._y, self._v, self._pre, self._len, self._ref)
            self._since += take
            row_end = row + int(np.searchsorted(ends[row:], self._base + self._len + take))
            if self._recorded:
                kernels.stream_record(self._len, take, self._base, w, self.hop_n, self.m, self._pre,
                                      self._s, self._c, self._n, self._h, self._rec_s, self._rec_c, self._rec_n,
                                      self._rec_h, k0 + row, sums[row:row_end], counts[row:row_end])
            else:
                fixed = running_sums.stream_update(
                    self._len, take, w, self.m, self._pre, self._s, self._c, self._n, self._err,
                    ends[row:row_end] - self._base, sums[row:row_end], counts[row:row_end])
                if fixed and row_end > row:
                    spans.append((row, row_end))
            self._len += take
            i += take
            row = row_end
        if spans and sum(b - a for a, b in spans) == len(ends) and all(
                np.array_equal(counts[a], counts[0]) for a, _ in spans):
            counts = np.broadcast_to(counts[0], counts.shape)  # no gap: one row of counts (read-only)
        else:
            for a, b in spans:
                counts[a + 1:b] = counts[a]
        n = self._base + self._len
        self._next_end = w - 1 + -(-(max(n, w - 1) - (w - 1)) // self.hop_n) * self.hop_n
        return ends, sums, counts

    def current(self) -> AdevResult:
        """Overlapping ADEV of the current (possibly still filling) window, whatever the
        hop: an exact recompute, O(window x taus)."""
        if self._staged:
            self.advance(np.zeros(0))  # the staged samples enter the engine (no window completes)
        n = min(self.n_pushed, self.window_n)
        sums, counts = kernels.window_sums_exact(self._pre, self._len - n, n, self.m)
        adev, lo, hi, edf = statistics(sums, counts, self.m, n, self.alpha, self.confidence)
        return AdevResult(self.m / self.sample_rate_hz, self.m, adev, lo, hi, edf, counts, self.sample_rate_hz, n,
                          self.confidence)
