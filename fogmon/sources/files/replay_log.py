"""A replay-log CSV replayed (docs/formats.md): its rows on the uniform sample grid, time
gaps as invalid placeholders, in the same blocks a live source would yield, as fast as
they can (the pipeline paces: ``realtime``; a replay log can also pace itself for use
outside it); an archive's pieces as one recording (``ReplayLogSet``)."""
from __future__ import annotations

import math
import os
from collections import deque
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from fogmon.block import Block, Event
from fogmon.errors import FogmonError
from fogmon.formats.recording import RATE_SAMPLES, check_grid_length, check_stated_rate, grid_positions, pick_axes
from fogmon.formats.replay_log import CHUNK_BYTES, ReplayLogReader, Rows
from fogmon.sources import plausibility
from fogmon.sources.base import OfflineSource
from fogmon.sources.grid import MAX_GAP_EVENTS, ErrorEvents
from fogmon.sources.options import SourceOptions
from fogmon.sources.pacing import Pacer

#: samples per block when replaying as fast as possible
FAST_BLOCK = 8192
#: block length (s) when paced
PACED_BLOCK_S = 0.1


def _block_len(sample_rate_hz: float, speed: float | None) -> int:
    return FAST_BLOCK if not speed else max(1, int(round(PACED_BLOCK_S * sample_rate_hz * speed)))


class ReplayLogSource(OfflineSource):
    """A replay-log CSV on its uniform grid, read in chunks (memory independent of the
    file size): time gaps become invalid placeholders with a ``gap`` event; rates beyond
    +-``max_abs_dph`` (deg/h, fogmon.sources.plausibility) become invalid samples. Opening
    reads the whole file once to check it (a bad row is a one-line error naming file,
    line and column before any work starts) and to know ``n_samples`` (grid length) and
    ``t_first_s``/``t_last_s``. A multi-axis log (``rate_<axis>_dph`` columns) gives
    multi-axis blocks; ``axis`` (a name or a comma list, ``pick_axes``) keeps
    those axes only, one of them as a one-axis block. ``axes``: the axes of the blocks
    (() for one axis). Counters, as far as the blocks yielded so far reach:
    ``samples`` (rows), ``samples_missing``, ``seq_gaps`` (time gaps), ``skipped_rows``
    (only with ``tolerate=True``), ``implausible_samples``. ``reader`` replaces the CSV
    reader of ``path`` by another of the same rows (a Parquet log: fogmon.formats.parquet_log)."""

    def __init__(self, path: str, speed: float | None = None, tolerate: bool = False,
                 max_abs_dph: float = plausibility.GENERIC_MAX_ABS_DPH, chunk_bytes: int = CHUNK_BYTES,
                 reader=None, axis: str | None = None, force_rate: bool = False) -> None:
        self._reader = reader = reader or ReplayLogReader(path, tolerate=tolerate, chunk_bytes=chunk_bytes)
        self.meta = reader.meta
        self._pick = pick_axes(reader.axes, axis, reader.name)
        self.axes = reader.axes if self._pick is None else self._pick if len(self._pick) > 1 else ()
        # the aux channels of the blocks: those of a placeholder block of the log, axes picked
        self.aux_names = list(self._picked(next(_seam_gap(0.0, 1, 1.0, reader.aux_names, reader.axes))).aux)
        self.sample_rate_hz = reader.sample_rate_hz
        self.name = f"replay log {reader.name}" + (f" ({reader.meta['sensor']})" if "sensor" in reader.meta else "")
        self._max_abs_dph = max_abs_dph
        t0: float | None = None
        t_last = math.nan
        last = -1
        rows_read = 0
        first: list[np.ndarray] = []   # the first RATE_SAMPLES time stamps: the stated rate's check
        jump: tuple[int, Any, int, float] = (0, None, 0, 0.0)  # largest grid step: (step, rows, row, s)
        for rows in reader.chunks():  # the checking pass
            if not len(rows):
                continue
            if t0 is None:
                t0 = float(rows.t_s[0])
            if rows_read < RATE_SAMPLES:
                first.append(rows.t_s[:RATE_SAMPLES - rows_read])
                if not force_rate and rows_read + len(rows) >= min(RATE_SAMPLES, 3):
                    check_stated_rate(self.meta, np.concatenate(first), reader.name)
            rows_read += len(rows)
            idx = grid_positions(rows.t_s, t0, self.sample_rate_hz, reader.name, last, rows.line_of)
            d = np.diff(idx, prepend=last if last >= 0 else idx[0])
            i = int(np.argmax(d))
            if d[i] > jump[0]:
                jump = (int(d[i]), rows, i, float(rows.t_s[i] - (rows.t_s[i - 1] if i else t_last)))
            last = int(idx[-1])
            t_last = float(rows.t_s[-1])
        if t0 is None:
            raise FogmonError(f"{reader.name}: no data rows")
        _, at, i, step = jump
        check_grid_length(last + 1, rows_read, reader.name,
                          jump=lambda: (at.line_of(i) if at is not None and at.line_of else None, step))
        self.t_first_s: float = t0
        self.t_last_s, self.n_samples = t_last, last + 1
        self.counters = {"samples": 0, "samples_missing": 0, "seq_gaps": 0, "skipped_rows": 0,
                         plausibility.COUNTER: 0}
        self._pacer = Pacer(speed)
        self._n = _block_len(self.sample_rate_hz, speed)
        self._closed = False

    def blocks(self) -> Iterator[Block]:
        c = self.counters
        errors = ErrorEvents(c)
        for b, present, gaps in self._grid_blocks():
            if self._closed:
                return
            self._pacer.wait(float(b.t_s[0]))
            c["samples"] += present
            c["samples_missing"] += len(b) - present
            c["seq_gaps"] += gaps
            b = self._picked(b)
            rate, n_bad = plausibility.gate(b.rate_dph, self._max_abs_dph)
            c[plausibility.COUNTER] += n_bad
            bad = np.isnan(rate) & b.valid
            first = bad.any(axis=1) if bad.ndim == 2 else bad
            t_event = float(b.t_s[np.argmax(first)])      # the first implausible sample's (or the block's)
            yield Block(b.t_s, rate, b.valid & ~bad, b.aux, b.events + tuple(errors.poll(t_event)), b.axes)

    def _picked(self, b: Block) -> Block:
        """A block of the log's columns with the axes ``axis`` keeps."""
        return b if self._pick is None else b.select(self._pick)

    def _grid_blocks(self) -> Iterator[tuple[Block, int, int]]:
        grid = _LogGrid(self.t_first_s, self.sample_rate_hz, self._n, self._reader.aux_names, self._reader.name,
                        self._reader.axes)
        for rows in self._reader.chunks():
            self.counters["skipped_rows"] += rows.skipped
            yield from grid.push(rows)
        yield grid.flush()

    def close(self) -> None:
        self._closed = True


class _LogGrid:
    """Checked rows of a replay log, in order -> blocks of ``n`` samples on the grid
    t0 + k / fs (s, Hz), block j holding grid indices j*n .. (j+1)*n - 1: missing samples
    are invalid placeholders (NaN) and each time gap is one ``gap`` event in the block
    where it starts, however many blocks it spans. The result does not depend on how
    the rows are cut into chunks. With ``axes``, the rate has one column per axis."""

    def __init__(self, t0_s: float, sample_rate_hz: float, n: int, aux_names: Sequence[str], name: str,
                 axes: tuple[str, ...] = ()) -> None:
        self.t0_s, self.sample_rate_hz, self.n, self.aux_names, self.name = (
            t0_s,
            sample_rate_hz,
            n,
            list(aux_names),
            name,
        )
        self.axes = axes
        self._last = -1
        self._gaps: deque[tuple[int, int]] = deque()  # (first missing grid index, samples missing)
        self._start(0)

    def _start(self, j: int) -> None:
        n = self.n
        self._j = j
        self._t = self.t0_s + (j * n + np.arange(n)) / self.sample_rate_hz
        self._rate = np.full((n, len(self.axes)) if self.axes else n, np.nan)
        self._aux = {k: np.full(n, np.nan) for k in self.aux_names}
        self._present = np.zeros(n, bool)

    def push(self, rows: Rows) -> Iterator[tuple[Block, int, int]]:
        """(block, samples present in it, time gaps starting in it) for every block the
        rows complete."""
        if not len(rows):
            return
        idx = grid_positions(rows.t_s, self.t0_s, self.sample_rate_hz, self.name, self._last, rows.line_of)
        d = np.diff(idx, prepend=self._last)
        g = np.flatnonzero(d > 1)
        self._gaps.extend(zip((idx[g] - d[g] + 1).tolist(), (d[g] - 1).tolist(), strict=True))
        self._last = int(idx[-1])
        j_of = idx // self.n
        cuts = [0, *(np.flatnonzero(np.diff(j_of)) + 1).tolist(), len(idx)]
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            j = int(j_of[a])
            while self._j < j:
                yield self._emit(self.n)
                self._start(self._j + 1)
            at = idx[a:b] - j * self.n
            self._t[at] = rows.t_s[a:b]
            self._rate[at] = rows.rate_dph[a:b]
            for k in self.aux_names:
                self._aux[k][at] = rows.aux[k][a:b]
            self._present[at] = True

    def flush(self) -> tuple[Block, int, int]:
        """The last block, up to the last row pushed."""
        return self._emit(self._last - self._j * self.n + 1)

    def _emit(self, m: int) -> tuple[Block, int, int]:
        end = self._j * self.n + self.n
        gaps = []
        while self._gaps and self._gaps[0][0] < end:
            gaps.append(self._gaps.popleft())
        t = self._t[:m]
        evs = [Event(float(t[k - end + self.n]), "gap", f"{n} sample(s) missing at t={t[k - end + self.n]:.6f} s "
                     f"(time gap in the log)") for k, n in gaps[:MAX_GAP_EVENTS]]
        if len(gaps) > MAX_GAP_EVENTS:
            evs.append(Event(evs[-1].t_s, "gap", f"{len(gaps) - MAX_GAP_EVENTS} more gaps in this block"))
        b = Block.make(t, self._rate[:m], aux={k: v[:m] for k, v in self._aux.items()}, events=evs, axes=self.axes)
        return b, int(np.count_nonzero(self._present[:m])), len(gaps)


class ReplayLogSet(OfflineSource):
    """Replay-log pieces (an archive's samples-NNNN.csv, fogmon.formats.archive) replayed as one
    recording, each read in chunks. Every piece is checked when the set is opened. The
    sample grid goes on across the seams: samples missing between two pieces become
    invalid placeholders with a ``gap`` event, as inside one log; pieces that overlap in
    time, or differ in sample rate or columns, are a one-line error. Counters: the
    pieces' summed, seam gaps included. ``axis``, ``axes``: as ReplayLogSource."""

    def __init__(self, paths: Sequence[str], tolerate: bool = False,
                 max_abs_dph: float = plausibility.GENERIC_MAX_ABS_DPH, axis: str | None = None) -> None:
        self.paths = list(paths)
        self._sources = [ReplayLogSource(p, tolerate=tolerate, max_abs_dph=max_abs_dph, axis=axis)
                         for p in self.paths]
        first = self._sources[0]
        self.sample_rate_hz = first.sample_rate_hz
        self.axes = first.axes
        aux = first.aux_names
        # neighbour pairs: prev is one longer than paths[1:] and sources[1:], the last is unused
        for path, prev, src in zip(self.paths[1:], self._sources, self._sources[1:], strict=False):
            if src.sample_rate_hz != self.sample_rate_hz:
                raise FogmonError(f"{path}: sample_rate_hz {src.sample_rate_hz:g} differs from {self.paths[0]} "
                                  f"({self.sample_rate_hz:g} Hz): not pieces of one recording")
            if src.aux_names != aux:
                raise FogmonError(f"{path}: columns {src.aux_names} differ from {self.paths[0]} ({aux})")
            if src._reader.rate_names != first._reader.rate_names:
                raise FogmonError(f"{path}: rate columns {src._reader.rate_names} differ from {self.paths[0]} "
                                  f"({first._reader.rate_names})")
            if _seam_missing(prev, src) < 0:
                raise FogmonError(f"{path}: starts at t={src.t_first_s:.6f} s, not after the end of the "
                                  f"previous piece (t={prev.t_last_s:.6f} s)")
        self.name = f"replay log {os.path.basename(self.paths[0])} .. {os.path.basename(self.paths[-1])} " \
                    f"({len(self.paths)} pieces)"
        self.n_samples = int(round((self._sources[-1].t_last_s - first.t_first_s) * self.sample_rate_hz)) + 1
        self._seams = {"samples_missing": 0, "seq_gaps": 0}
        self._closed = False

    @property
    def counters(self) -> dict[str, int]:
        out = dict(self._seams)
        for src in self._sources:
            for k, v in src.counters.items():
                out[k] = out.get(k, 0) + v
        return out

    def blocks(self) -> Iterator[Block]:
        for i, src in enumerate(self._sources):
            missing = _seam_missing(self._sources[i - 1], src) if i else 0
            if missing:
                self._seams["samples_missing"] += missing
                self._seams["seq_gaps"] += 1
                yield from map(src._picked, _seam_gap(self._sources[i - 1].t_last_s, missing, self.sample_rate_hz,
                                                      src._reader.aux_names, src._reader.axes))
            for b in src.blocks():
                if self._closed:
                    return
                yield b

    def close(self) -> None:
        self._closed = True


def _seam_missing(prev: ReplayLogSource, nxt: ReplayLogSource) -> int:
    """Samples missing between the end of piece ``prev`` and the start of ``nxt``."""
    return int(round((nxt.t_first_s - prev.t_last_s) * prev.sample_rate_hz)) - 1


def _seam_gap(t_end: float, missing: int, sample_rate_hz: float, aux: list[str],
              axes: tuple[str, ...] = ()) -> Iterator[Block]:
    """Invalid placeholders for the samples missing between two pieces, FAST_BLOCK at a
    time, with a gap event in the first."""
    for i in range(0, missing, FAST_BLOCK):
        t = t_end + np.arange(i + 1, min(i + FAST_BLOCK, missing) + 1) / sample_rate_hz
        nan = np.full(len(t), np.nan)
        rate = np.full((len(t), len(axes)), np.nan) if axes else nan
        ev = (Event(float(t[0]), "gap", f"{missing} sample(s) missing at t={t[0]:.6f} s (between two pieces)"),)
        yield Block(t, rate, np.zeros(rate.shape, bool), {k: nan for k in aux}, ev if i == 0 else (), axes)


def open_source(path: str, opts: SourceOptions) -> ReplayLogSource:
    """The replay-log CSV ``path`` (``tolerate_bad_rows``, ``file_gate_dph``, ``axis``)."""
    return ReplayLogSource(path, tolerate=opts.tolerate_bad_rows, max_abs_dph=opts.file_gate_dph, axis=opts.axis,
                           force_rate=opts.force_rate)
