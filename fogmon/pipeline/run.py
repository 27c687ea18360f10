"""One run (``Pipeline``, ``run_pipeline``) as `fogmon replay` and `fogmon monitor` make it:
source -> StreamingDadev (ring-buffer DAVAR) -> fit_noise per completed window -> sinks.

A live gyro and a replay differ only in the source. Blocks are processed as they come
(Python overhead per block, not per sample); every completed window (one per hop) is
fitted with the IEEE-952 model and handed to the sinks with its recording time; the run
ends at the end of the source, at ``duration_s`` of recording time, or on Ctrl-C
(SIGTERM, SIGHUP: fogmon.stopping), and always closes the source and the sinks so the
.rrd and the archive are complete. With ``rotate_s`` blocks are cut where a new piece
of the outputs begins and the sinks are told (``Sink.rotate``) before its first block.
A stream of several axes (``Block.axes``) runs one engine, fit, motion gate, live
methods and model check per axis (``AxisAnalysis``), each equal to a one-axis run of
that axis.
"""
from __future__ import annotations

import math
import time
import warnings
from collections import Counter
from collections.abc import Iterable, Sequence

import numpy as np

from fogmon import startup, stopping
from fogmon.block import Block, Event
from fogmon.davar.result import DadevResult
from fogmon.errors import FogmonError, FogmonWarning
from fogmon.modelcheck import ModelBand
from fogmon.pipeline.accel import AccelAnalysis, accel_channels
from fogmon.pipeline.axis import AxisAnalysis
from fogmon.pipeline.config import PipelineConfig, _check_axis_options, live_samples, window_and_hop
from fogmon.pipeline.progress import ReplayProgress
from fogmon.pipeline.reader import _ThreadedBlocks
from fogmon.sim.model import SensorModel
from fogmon.sinks.base import AccelSummary, AxisSummary, Sink, StopRun, StreamInfo, Summary
from fogmon.sources.base import Source
from fogmon.sources.pacing import Pacer

#: What DAVAR analyses when the recording has a reference rotation.
ERROR_EXPR = "rate_dph - 3600 x rot_dps"
#: A live run with ``duration_s`` also stops reading the device this long (s, or 10 % more)
#: after that much wall time from opening the source, should the device fall silent (what
#: was read is kept).
LIVE_WALL_SLACK_S = 2.0


class Pipeline:
    """One run of ``source`` into sinks, split by event the way can.Notifier is: ``run``
    reads the source (a reader thread for a live one) and calls ``start`` before the first
    block, ``block`` for each block (which hands completed windows to ``frames``) and
    ``close`` at the end, whatever happens. Options are checked when it is built, before
    any sink or device is opened. Each axis of the stream (``axes``: the source's, or
    its first block's) is analysed by its own AxisAnalysis (``analyses``)."""

    def __init__(self, source: Source, config: PipelineConfig | None = None,
                 pacer: Pacer | None = None) -> None:
        config = PipelineConfig() if config is None else config
        self.source, self.config = source, config
        self.sample_rate_hz = sample_rate_hz = float(source.sample_rate_hz)
        self.total_n = source.n_samples
        self.window_s, self.hop_s = window_and_hop(config, sample_rate_hz, self.total_n, source.name)
        rotate_s = config.rotate_s
        self.piece_n = int(round(rotate_s * sample_rate_hz)) if rotate_s else None
        if self.piece_n is not None and self.piece_n < 1:
            raise FogmonError(f"`rotate_s` {rotate_s:g} s is shorter than one sample at {sample_rate_hz:g} Hz")
        self.pacer = pacer if pacer is not None else Pacer(config.realtime)
        self.sinks: list[Sink] = []
        self.summary = Summary(source.name, sample_rate_hz, self.window_s, self.hop_s)
        self.axes: tuple[str, ...] = ()
        self.analyses: list[AxisAnalysis] = []
        self.accels: dict[str, list[AccelAnalysis]] = {}   # gyro axis ("": one axis) -> accelerometers following it
        self._set_axes(tuple(source.axes))  # checks taus, builds the model bands
        self.started = self.done = self.use_ref = False
        self.t_origin = math.nan      # recording time of the first sample (s), once it came
        self.piece = 1
        self.reader: _ThreadedBlocks | None = None
        self.source_closed_early = False
        self._counts: Counter = Counter()
        self._t_frames: float | None = None   # end (s) of the latest window not yet followed by counters

    def _set_axes(self, axes: tuple[str, ...]) -> None:
        """One AxisAnalysis per axis of the stream (one named "" for a one-axis stream);
        FogmonError when an option cannot apply to these axes."""
        cfg = self.config
        _check_axis_options(cfg, axes, self.source.name)
        self.axes = axes
        self.summary.axes = {a: AxisSummary() for a in axes}
        bands: list[tuple[SensorModel, ModelBand]] = []   # one band per distinct axis model
        self.analyses = []
        for name in axes or ("",):
            analysis = AxisAnalysis(name, self.sample_rate_hz, self.window_s, self.hop_s, cfg,
                                    self.summary.axes[name] if name else self.summary)
            if cfg.model is not None:
                model = cfg.model.for_axis(name) if name else cfg.model
                band = next((b for m, b in bands if m == model), None)
                if band is None:
                    band = ModelBand.for_model(model, self.sample_rate_hz, analysis.engine.window_n,
                                               analysis.engine.m, alpha=cfg.model_alpha)
                    bands.append((model, band))
                analysis.band = band
            self.analyses.append(analysis)

    # -- the loop ------------------------------------------------------------------
    def run(self, sinks: Sequence[Sink]) -> Summary:
        """Stream the source through DAVAR and the noise fit into ``sinks``; returns the
        Summary. The source and all sinks are closed whatever happens."""
        cfg, sample_rate_hz = self.config, self.sample_rate_hz
        self.sinks = list(sinks)
        total_s = min(self.total_n / sample_rate_hz, cfg.duration_s or math.inf) if self.total_n else 0.0
        self.progress = ReplayProgress(total_s, enabled=cfg.progress)
        self.wall0 = self.wall_start = time.monotonic()
        try:
            for big in self._blocks():
                if not self._take(big):
                    break
        except KeyboardInterrupt:
            self.summary.interrupted = True
        except StopRun as e:       # an output can take no more: end as a stop signal does
            self.summary.stopped = str(e)
        except BaseException:
            self.summary.failed = True
            raise
        finally:
            self.close()
        return self.summary

    def _blocks(self) -> Iterable[Block]:
        """The source's blocks; a live one compiles the kernels first, is cut at
        ``duration_s`` and read in a thread."""
        cfg = self.config
        if self.total_n is None:
            with startup.loading():
                _warm_up(self.sample_rate_hz, self.window_s, self.hop_s, cfg.taus)
            if cfg.duration_s is not None and self.source.live:
                self.source.limit(live_samples(cfg.duration_s, self.sample_rate_hz))  # nothing after the cut is read
            self.reader = _ThreadedBlocks(self.source)
        self.wall_start = time.monotonic()
        return self.reader if self.reader is not None else self.source.blocks()

    def _take(self, big: Block) -> bool:
        """Process one block of the source; False when the run is complete."""
        cfg, sample_rate_hz = self.config, self.sample_rate_hz
        self._check_wall_limit()
        if not len(big):
            self._dispatch(big.events)
            return True
        if math.isnan(self.t_origin):
            self.t_origin = float(big.t_s[0])
            self.pacer.wait(self.t_origin)
        if cfg.duration_s is not None:
            stop = int(np.searchsorted(big.t_s, self.t_origin + cfg.duration_s - 0.5 / sample_rate_hz, side="right"))
            if stop < len(big):
                big, self.done = big.slice(0, stop), True
                if not stop:
                    return False
        for b_piece, b in _at_seams(
            _paced(big, cfg.realtime, sample_rate_hz), self.t_origin, sample_rate_hz, self.piece_n
        ):
            self.pacer.wait(float(b.t_s[-1]))
            with stopping.shielded():  # a block reaches every sink, or none: stop between blocks
                if not self.started:
                    with startup.loading():    # the first block loads Rerun and the numba kernels
                        self.start(b)
                        self.block(b, b_piece)
                else:
                    self.block(b, b_piece)
        return not self.done

    def _check_wall_limit(self) -> None:
        """A live source that stalls still stops on time with ``duration_s`` (what it read
        is kept): closed after the run's duration plus LIVE_WALL_SLACK_S of wall time."""
        duration_s = self.config.duration_s
        if duration_s is None or self.total_n is not None or self.source_closed_early:
            return
        opened = self.source.opened_s or self.wall_start
        if time.monotonic() > opened + duration_s + max(LIVE_WALL_SLACK_S, 0.1 * duration_s):
            self.source.close()
            self.source_closed_early = True

    # -- events ----------------------------------------------------------------------
    def start(self, first: Block) -> None:
        """Before the first block: what is analysed (per axis when the block has axes),
        StreamInfo to the sinks."""
        from fogmon.davar.taus import tau_grid

        sample_rate_hz = self.sample_rate_hz
        if first.axes != self.axes:
            self._set_axes(first.axes)
        model = self.config.model
        if not self.axes and model is not None and model.axes:
            warnings.warn(f"`model` has [noise.<axis>] tables ({', '.join(model.axes)}) and {self.source.name} is "
                          f"one axis: it is checked against the model's [noise] table and every effect (`axis` NAME "
                          f"picks an axis's model)", FogmonWarning, stacklevel=2)
        m = tau_grid(sample_rate_hz, int(round(self.window_s * sample_rate_hz)), self.config.taus)
        views = [first.axis(a.name) if a.name else first for a in self.analyses]
        self.use_ref = any("rot_dps" in v.aux for v in views) and not self.config.raw_rate
        self.summary.analysed = ERROR_EXPR if self.use_ref else "rate_dph"
        aux_names = tuple(first.aux)
        for a, view in zip(self.analyses, views, strict=True):
            aux_names += a.start(tuple(view.aux), self.source.name)
        if any(a.conditioner is not None and a.conditioner.thermal is not None for a in self.analyses):
            self.summary.analysed += " - thermal drift"
        bands = {a.name: (a.band.lo_dph, a.band.median_dph, a.band.hi_dph) for a in self.analyses
                 if a.band is not None}
        self._set_accels(tuple(first.aux))
        info = StreamInfo(self.source.name, sample_rate_hz, self.window_s, self.hop_s, m / sample_rate_hz, aux_names,
                          self.summary.analysed, bands, self.config.model_alpha if bands else None, self.axes,
                          tuple(self.summary.accels))
        for s in self.sinks:
            s.start(info)
        self.started = True
        self.summary.t_first_s = float(first.t_s[0])

    def _set_accels(self, aux_names: tuple[str, ...]) -> None:
        """One AccelAnalysis per accelerometer channel (``accel_<name>_g``; ``accels``
        chooses), following the motion gate of the gyro axis of its name, else of the
        first axis."""
        self.accels = {}
        for name, channel in accel_channels(aux_names, self.config.accels).items():
            summary = self.summary.accels[name] = AccelSummary()
            follows = name if name in self.axes else self.analyses[0].name
            self.accels.setdefault(follows, []).append(AccelAnalysis(
                name, channel, self.sample_rate_hz, self.window_s, self.hop_s, self.config.taus, summary))

    def block(self, b: Block, b_piece: int) -> None:
        """One block of piece ``b_piece``: each axis through the live methods, to the
        sinks, then each axis (motion-gated) to DAVAR."""
        prepared = [a.prepare(b, self.use_ref) for a in self.analyses]
        channels = {k: v for p in prepared for k, v in p.channels.items()}
        events = tuple(e for p in prepared for e in p.events)
        if channels or events:
            b = Block(b.t_s, b.rate_dph, b.valid, {**b.aux, **channels}, (*b.events, *events), b.axes)
        self._deliver(b, b_piece)
        for accels in self.accels.values():
            for acc in accels:
                acc.push(b.aux, len(b))
        for a, p in zip(self.analyses, prepared, strict=True):
            self._analyse(a, *a.gate(b.t_s, p.rate_dph, p.valid, self._dispatch))
        self._send_counters()
        self.progress.update(self.summary.duration_s, time.monotonic() - self.wall0)

    def frames(self, analysis: AxisAnalysis, res: DadevResult) -> None:
        """Completed windows of one axis: fitted, handed to the sinks with their end times
        (and the axis name when the stream has axes), jump and model-band events."""
        from fogmon.davar.fit import fit_noise

        fit = fit_noise(res)
        t_end = self.t_origin + np.asarray(res.end_index, dtype=np.float64) / self.sample_rate_hz
        name = analysis.name
        for s in self.sinks:
            if name:
                s.frames(res, fit, t_end, axis=name)
            else:  # a one-axis stream: as before axes existed
                s.frames(res, fit, t_end)
        analysis.summary.n_windows += len(res)
        self._dispatch(analysis.named(analysis.jumps.update(fit, t_end)))
        if analysis.aux_windows is not None:
            self._dispatch(analysis.named(analysis.window_checks(res, fit, t_end)))
        self._t_frames = float(t_end[-1])

    def accel_frames(self, acc: AccelAnalysis, res: DadevResult) -> None:
        """Completed windows of one accelerometer: fitted, handed to the sinks with their end times."""
        fit = acc.fit(res)
        t_end = self.t_origin + np.asarray(res.end_index, dtype=np.float64) / self.sample_rate_hz
        for s in self.sinks:
            s.accel_frames(res, fit, t_end, acc.name)
        self._t_frames = float(t_end[-1])

    def close(self) -> None:
        """End of the run: the source closed, what a live reader still held and the
        motion gate's last samples analysed, the whole-run ADEV, the sinks finished."""
        stopping.closing()  # a further Ctrl-C/SIGTERM must not cut the outputs short
        summary = self.summary
        self.progress.update(summary.duration_s, time.monotonic() - self.wall0)
        self.progress.close()
        self.source.close()
        ok = self.started and not summary.failed
        if self.reader is not None:
            backlog = self.reader.backlog()
            if ok and not self.done:  # read before the stop: archived, not analysed
                self._drain(backlog)
        for a in self.analyses:
            if a.motion is not None and ok:   # the samples the gate still holds
                self._analyse(a, *a.flush_gate(self._dispatch))
        if ok:
            self._send_counters()
        summary.wall_s = time.monotonic() - self.wall0
        summary.source_wall_s = time.monotonic() - self.wall_start
        summary.counters = self._counters()
        summary.event_counts = dict(self._counts)
        if self.axes:
            summary.n_windows = max(a.summary.n_windows for a in self.analyses)
        try:
            for a in self.analyses:
                if a.watch is not None:
                    a.summary.model_check = a.watch.summary()
                if a.phases is not None:
                    a.summary.phases = a.phases.summary()
                a.overall(self.summary.t_last_s, self.config.taus)
            for accels in self.accels.values():
                for acc in accels:
                    acc.overall(self.summary.t_last_s, self.config.taus)
        finally:
            for s in sorted(self.sinks, key=lambda k: k.finish_order):
                s.finish(summary)

    # -- helpers ---------------------------------------------------------------------
    def _drain(self, backlog: list[Block]) -> None:
        """Blocks a live reader read before the stop: delivered and counted."""
        for big in backlog:
            if not len(big):
                self._dispatch(big.events)
                continue
            for b_piece, b in _at_seams([big], self.t_origin, self.sample_rate_hz, self.piece_n):
                self._deliver(b, b_piece)

    def _analyse(self, a: AxisAnalysis, y: np.ndarray, valid: np.ndarray, moved: np.ndarray | None) -> None:
        """DAVAR, fits, jump and model-band events of axis ``a`` for its next samples
        (``moved``: those the motion gate made invalid)."""
        res = a.analyse(y, valid, moved)
        if len(res):
            self.frames(a, res)
        for acc in self.accels.get(a.name, ()):
            res = acc.analyse(a.moving)
            if len(res):
                self.accel_frames(acc, res)

    def _send_counters(self) -> None:
        """The counters to the sinks, once after the windows a block completed (if any)."""
        if self._t_frames is None:
            return
        counters = self._counters()
        for s in self.sinks:
            s.source_counters(self._t_frames, counters)
        self._t_frames = None

    def _counters(self) -> dict[str, int]:
        """The source's counters, the reader's (dropped blocks) and the live methods' (per
        axis as ``<counter>_<axis>`` when the stream has axes)."""
        c = {**self.source.counters, **(self.reader.counters if self.reader is not None else {})}
        for a in self.analyses:
            c.update({a.suffixed(k): v for k, v in a.counters().items()})
        return c

    def _deliver(self, b: Block, b_piece: int) -> None:
        """Hand a block to the sinks (after ``rotate`` when it begins piece ``b_piece``)
        and count it in the summary."""
        if b_piece != self.piece:
            for s in self.sinks:
                s.rotate(b_piece, float(b.t_s[0]))
            self.piece = b_piece
        if len(b):
            summary = self.summary
            summary.n_samples += len(b)
            if b.axes:
                summary.n_invalid += int(len(b) - np.count_nonzero(b.valid.all(axis=1)))
                for j, a in enumerate(b.axes):
                    summary.axes[a].n_invalid += int(len(b) - np.count_nonzero(b.valid[:, j]))
            else:
                summary.n_invalid += int(len(b) - np.count_nonzero(b.valid))
            summary.t_last_s = float(b.t_s[-1])
            for s in self.sinks:
                s.block(b)
        self._dispatch(b.events)

    def _dispatch(self, events: Sequence[Event]) -> None:
        if not events:
            return
        self._counts.update(e.kind for e in events)
        for s in self.sinks:
            s.events(events)


def run_pipeline(source: Source, config: PipelineConfig, sinks: Sequence[Sink], pacer: Pacer | None = None) -> Summary:
    """Stream ``source`` through DAVAR and the noise fit into ``sinks`` (Pipeline)."""
    return Pipeline(source, config, pacer).run(sinks)


def _warm_up(sample_rate_hz: float, window_s: float, hop_s: float, taus) -> None:
    """Compile/load the engine's kernels on a throw-away instance before the source is
    opened, so a live device is not left unread while they compile."""
    from fogmon.davar.fit import fit_noise
    from fogmon.davar.streaming import StreamingDadev

    n = int(round(window_s * sample_rate_hz)) + int(round(hop_s * sample_rate_hz))
    if n > 1 << 22:
        return
    res = StreamingDadev(sample_rate_hz, window_s, taus=taus, hop_s=hop_s).push(
        np.random.default_rng(0).standard_normal(n))
    if len(res):
        fit_noise(res)


def _paced(b: Block, realtime: float | None, sample_rate_hz: float):
    """Split a block into pieces of <= 0.1 s of wall time when pacing, else pass it on."""
    if not realtime:
        yield b
        return
    step = max(1, int(0.1 * realtime * sample_rate_hz))
    for i in range(0, len(b), step):
        yield b.slice(i, min(i + step, len(b)))


def _at_seams(blocks: Iterable[Block], t_origin: float, sample_rate_hz: float, piece_n: int | None):
    """(piece, block) pairs, blocks cut where a new piece of ``piece_n`` samples begins
    (piece 1 starts at ``t_origin``; ``piece_n`` None: one piece)."""
    for b in blocks:
        if not piece_n:
            yield 1, b
            continue
        k = np.rint((b.t_s - t_origin) * sample_rate_hz).astype(np.int64) // piece_n
        cuts = [0, *(np.flatnonzero(np.diff(k)) + 1), len(b)]
        for i, j in zip(cuts[:-1], cuts[1:], strict=True):
            yield int(k[i]) + 1, (b if j - i == len(b) else b.slice(i, j))
