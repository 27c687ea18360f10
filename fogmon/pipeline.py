"""The streaming pipeline shared by `fogmon replay` and `fogmon monitor`:
source -> StreamingDadev (ring-buffer DAVAR) -> fit_noise per completed window -> sinks.

A live gyro and a replay differ only in the source. Blocks are processed as they come
(Python overhead per block, not per sample); every completed window (one per hop) is
fitted with the IEEE-952 model and handed to the sinks with its recording time; the run
ends at the end of the source, at ``--duration-s`` of recording time, or on Ctrl-C
(SIGTERM, SIGHUP: fogmon.stopping), and always closes the source and the sinks so the
.rrd and the archive are complete. With ``--rotate-s`` blocks are cut where a new piece
of the outputs begins and the sinks are told (``Sink.rotate``) before its first block.
A stream of several axes (``Block.axes``) runs one engine, fit, motion gate, live
methods and model check per axis (``AxisAnalysis``), each equal to a one-axis run of
that axis.
"""
from __future__ import annotations

import math
import sys
import threading
import time
import warnings
from collections import Counter, deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import TextIO

import numpy as np

from fogmon import startup, stopping
from fogmon.block import Block, Event
from fogmon.davar.fit import NoiseFit
from fogmon.davar.jumps import JumpDetector
from fogmon.davar.result import DadevResult
from fogmon.errors import FogmonError, FogmonWarning
from fogmon.methods.live import Conditioner, LiveMethods
from fogmon.modelcheck import AuxWindows, ModelBand, ModelWatch
from fogmon.phases import STATE_CHANNELS, PhaseLog
from fogmon.sim.model import SensorModel
from fogmon.sinks.base import AxisSummary, Sink, StreamInfo, Summary
from fogmon.sources.base import Source
from fogmon.sources.live import LiveSource
from fogmon.sources.pacing import Pacer

#: What ``--taus`` gives ``tau_grid``: a grid name, N per decade, or tau values in s.
TauSpec = str | int | np.ndarray
#: Default window bounds in samples (the window is a power of two inside these).
MIN_WINDOW_SAMPLES = 2**10
MAX_WINDOW_SAMPLES = 2**20
#: Live default window in samples (65.5 s at 1 kHz, 655 s at 100 Hz).
LIVE_WINDOW_SAMPLES = 2**16
#: What DAVAR analyses when the recording has a reference rotation.
ERROR_EXPR = "rate_dph - 3600 x rot_dps"
#: A live run with --duration-s also stops reading the device this long (s, or 10 % more)
#: after that much wall time from opening the source, should the device fall silent (what
#: was read is kept).
LIVE_WALL_SLACK_S = 2.0
#: The whole-run ADEV of the console summary keeps at most this many samples (the latest).
OVERALL_MAX_SAMPLES = 2**22
#: Samples read but not yet processed that a live run or an endless simulation may hold
#: (2**20: 17 min at 1 kHz); beyond it a simulation waits and a live device's blocks are
#: dropped, counted and reported.
QUEUE_MAX_SAMPLES = 2**20
#: Placeholders for dropped samples come in blocks of at most this many samples.
PLACEHOLDER_BLOCK = 2**16
#: Events of dropped blocks kept (the rest are counted in the ``dropped`` event).
DROPPED_EVENTS_KEPT = 1000


# ----------------------------------------------------------------------------- windows
def default_window_s(sample_rate_hz: float, n_samples: int | None) -> float:
    """Default window in s: for a record of ``n_samples`` a quarter of it rounded down to a
    power of two of samples (within MIN..MAX_WINDOW_SAMPLES, never longer than the record);
    live (``n_samples`` None) LIVE_WINDOW_SAMPLES."""
    if n_samples is None:
        return LIVE_WINDOW_SAMPLES / sample_rate_hz
    quarter = max(n_samples // 4, 1)
    n = 2 ** int(math.floor(math.log2(quarter)))
    n = min(max(n, MIN_WINDOW_SAMPLES), MAX_WINDOW_SAMPLES, n_samples)
    return n / sample_rate_hz


def window_and_hop(config: PipelineConfig, sample_rate_hz: float, total_n: int | None) -> tuple[float, float]:
    """Window and hop (s) from ``--window-s``/``--hop-s`` or their defaults, checked
    against the sample rate and the samples the run will have (the record's ``total_n``,
    None when live, cut to ``--duration-s``); FogmonError naming the option otherwise."""
    duration_s = config.duration_s
    n_run = total_n
    if duration_s is not None:
        n_cut = round(duration_s * sample_rate_hz)
        if n_cut < 1:
            raise FogmonError(f"--duration-s {duration_s:g} s is shorter than one sample at {sample_rate_hz:g} Hz")
        n_run = n_cut if total_n is None else min(total_n, n_cut)
    if n_run is not None and n_run < 8:
        what = "the recording has" if n_run == total_n else "--duration-s leaves"
        raise FogmonError(f"{what} {n_run} samples at {sample_rate_hz:g} Hz: an Allan deviation needs at least 8")
    window_s = config.window_s
    if window_s is None:
        window_s = default_window_s(sample_rate_hz, n_run)
        if total_n is None:  # live: the live window unless --duration-s asks for a shorter run
            window_s = min(window_s, default_window_s(sample_rate_hz, None))
    if n_run is not None and window_s * sample_rate_hz > n_run:
        what = "the recording" if n_run == total_n else "the --duration-s run"
        raise FogmonError(f"--window-s {window_s:g} s is longer than {what} "
                          f"({n_run / sample_rate_hz:g} s = {n_run} samples)")
    if window_s * sample_rate_hz < 8:
        raise FogmonError(f"--window-s {window_s:g} s holds fewer than 8 samples at {sample_rate_hz:g} Hz")
    hop_s = config.hop_s or window_s / 8
    if hop_s * sample_rate_hz < 1:
        raise FogmonError(f"--hop-s {hop_s:g} s is shorter than one sample at {sample_rate_hz:g} Hz")
    if hop_s > window_s:
        raise FogmonError(f"--hop-s {hop_s:g} s is longer than the window ({window_s:g} s): the samples "
                          f"between windows would never be analysed")
    return window_s, hop_s


# ----------------------------------------------------------------------------- helpers
class ReplayProgress:
    """A replay's progress bar on ``stream`` (default stderr, tqdm): recording seconds
    done of ``total_s`` and the speed in x real time. Shown only when ``enabled`` (the
    caller checks that stderr is a terminal) and the total is known."""

    FORMAT = "{percentage:5.1f}%|{bar:30}| {n:.1f}/{total:.1f} s of recording{postfix} [{elapsed}<{remaining}]"

    def __init__(self, total_s: float, enabled: bool, stream: TextIO | None = None):
        self._bar = None
        if enabled and total_s > 0:   # tqdm imported only to be shown
            from tqdm import tqdm

            self._bar = tqdm(total=total_s, file=stream or sys.stderr, mininterval=0.2, bar_format=self.FORMAT)

    def update(self, done_s: float, wall_s: float) -> None:
        """``done_s`` s of recording analysed in ``wall_s`` s of wall time."""
        if self._bar is None:
            return
        if wall_s > 0:
            self._bar.set_postfix_str(f"x{done_s / wall_s:,.0f} real time", refresh=False)
        self._bar.update(min(done_s, self._bar.total) - self._bar.n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


# ----------------------------------------------------------------------------- run
@dataclass(frozen=True)
class PipelineConfig:
    """How a run analyses and paces (built from the command line by fogmon.cli, or by hand):
    ``window_s``/``hop_s`` (s; None = default_window_s and window/8), ``taus`` (what
    ``tau_grid`` takes), ``raw_rate`` (analyse rate_dph even with rot_dps), ``keep_motion``
    (no motion gate), ``duration_s`` (stop after this much recording time, s),
    ``realtime`` (pace at this many times real time; None = as fast as possible),
    ``rotate_s`` (new output pieces every this many s of recording time; None = one),
    ``progress`` (a progress bar on stderr), ``methods`` (thermal correction, outlier
    rejection, Kalman channel: fogmon.methods.live; ``axis_methods``: an axis's own, for
    the axes of a stream of several axes it names), ``model`` (check every window
    against the model's DADEV band at family-wise ``model_alpha`` per window:
    fogmon.modelcheck)."""

    window_s: float | None = None
    hop_s: float | None = None
    taus: TauSpec = "octave"
    raw_rate: bool = False
    keep_motion: bool = False
    duration_s: float | None = None
    realtime: float | None = None
    rotate_s: float | None = None
    progress: bool = False
    methods: LiveMethods = LiveMethods()
    axis_methods: dict[str, LiveMethods] = field(default_factory=dict)
    model: SensorModel | None = None
    model_alpha: float = 0.01


def _check_axis_options(cfg: PipelineConfig, axes: tuple[str, ...], source_name: str) -> None:
    """FogmonError naming the option when a one-axis --thermal-cal, a per-axis calibration
    or a --model of several axes does not cover the stream's ``axes`` (() = one axis)."""
    if axes and cfg.methods.thermal is not None:
        raise FogmonError(f"--thermal-cal: the calibration is for one axis and {source_name} has axes "
                          f"{', '.join(axes)}: select one with --axis NAME")
    calibrated = sorted(a for a, m in cfg.axis_methods.items() if m.thermal is not None)
    if calibrated and set(axes) - set(calibrated):
        what = f"not for {', '.join(a for a in axes if a not in calibrated)}" if axes else f"{source_name} is one axis"
        raise FogmonError(f"--thermal-cal: the calibration has a thermal_drift effect for axes "
                          f"{', '.join(calibrated)} and {what}: select calibrated axes with --axis")
    if axes and cfg.model is not None:
        missing = [a for a in axes if cfg.model.axes and a not in cfg.model.axes]
        if missing:
            raise FogmonError(f"--model: the model has no [noise.{missing[0]}] table (its axes: "
                              f"{', '.join(cfg.model.axes)}; the stream's: {', '.join(axes)}); "
                              f"select one of its axes with --axis NAME")


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
        self.window_s, self.hop_s = window_and_hop(config, sample_rate_hz, self.total_n)
        rotate_s = config.rotate_s
        self.piece_n = int(round(rotate_s * sample_rate_hz)) if rotate_s else None
        if self.piece_n is not None and self.piece_n < 1:
            raise FogmonError(f"--rotate-s {rotate_s:g} s is shorter than one sample at {sample_rate_hz:g} Hz")
        self.pacer = pacer if pacer is not None else Pacer(config.realtime)
        self.sinks: list[Sink] = []
        self.summary = Summary(source.name, sample_rate_hz, self.window_s, self.hop_s)
        self.axes: tuple[str, ...] = ()
        self.analyses: list[AxisAnalysis] = []
        self._set_axes(tuple(source.axes))  # checks --taus, builds the model bands
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
        except BaseException:
            self.summary.failed = True
            raise
        finally:
            self.close()
        return self.summary

    def _blocks(self) -> Iterable[Block]:
        """The source's blocks; a live one compiles the kernels first, is cut at
        --duration-s and read in a thread."""
        cfg = self.config
        if self.total_n is None:
            with startup.loading():
                _warm_up(self.sample_rate_hz, self.window_s, self.hop_s, cfg.taus)
            if cfg.duration_s is not None and isinstance(self.source, LiveSource):
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
        """A live source that stalls still stops on time with --duration-s (what it read
        is kept): closed after the run's duration plus LIVE_WALL_SLACK_S of wall time."""
        duration_s = self.config.duration_s
        if duration_s is None or self.total_n is not None or self.source_closed_early:
            return
        opened = (self.source.opened_s if isinstance(self.source, LiveSource) else None) or self.wall_start
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
            warnings.warn(f"--model has [noise.<axis>] tables ({', '.join(model.axes)}) and {self.source.name} is "
                          f"one axis: it is checked against the model's [noise] table and every effect (--axis NAME "
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
        info = StreamInfo(self.source.name, sample_rate_hz, self.window_s, self.hop_s, m / sample_rate_hz, aux_names,
                          self.summary.analysed, bands, self.config.model_alpha if bands else None, self.axes)
        for s in self.sinks:
            s.start(info)
        self.started = True
        self.summary.t_first_s = float(first.t_s[0])

    def block(self, b: Block, b_piece: int) -> None:
        """One block of piece ``b_piece``: each axis through the live methods, to the
        sinks, then each axis (motion-gated) to DAVAR."""
        prepared = [a.prepare(b, self.use_ref) for a in self.analyses]
        channels = {k: v for p in prepared for k, v in p.channels.items()}
        events = tuple(e for p in prepared for e in p.events)
        if channels or events:
            b = Block(b.t_s, b.rate_dph, b.valid, {**b.aux, **channels}, (*b.events, *events), b.axes)
        self._deliver(b, b_piece)
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
                y, valid, ev = a.motion.flush()
                self._dispatch(a.named(ev))
                self._analyse(a, y, valid)
                a.summary.motion_spans, a.summary.motion_samples = list(a.motion.spans), a.motion.samples_excluded
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

    def _analyse(self, a: AxisAnalysis, y: np.ndarray, valid: np.ndarray) -> None:
        """DAVAR, fits, jump and model-band events of axis ``a`` for its next samples."""
        res = a.analyse(y, valid)
        if len(res):
            self.frames(a, res)

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


@dataclass(frozen=True)
class _Prepared:
    """One axis of a block after the live methods: the rate to analyse (deg/h), its
    valid flags, the channels and events the methods add."""

    rate_dph: np.ndarray
    valid: np.ndarray
    channels: dict[str, np.ndarray]
    events: tuple[Event, ...]


class AxisAnalysis:
    """The analysis of one axis in a run (``name`` "" for a one-axis stream): live
    methods, motion gate, streaming DAVAR, coefficient-jump events, model check (``band``,
    set by the pipeline) and the whole-run tail, writing its account into ``summary``.
    Each axis of a multi-axis stream has its own, so each axis's results equal those of
    a one-axis run of that axis (``Block.axis``). Channels the methods add and counters
    are named ``<name>_<axis>``, events carry the axis."""

    def __init__(self, name: str, sample_rate_hz: float, window_s: float, hop_s: float, config: PipelineConfig,
                 summary: AxisSummary) -> None:
        from fogmon.davar.streaming import StreamingDadev
        from fogmon.motion import MotionGate

        self.name, self.summary, self.sample_rate_hz = name, summary, sample_rate_hz
        self.engine = StreamingDadev(sample_rate_hz, window_s, taus=config.taus, hop_s=hop_s)  # checks --taus
        self.jumps = JumpDetector(window_s)
        self.tail = _Tail(OVERALL_MAX_SAMPLES)
        self.motion = None if config.keep_motion else MotionGate(sample_rate_hz)
        methods = config.axis_methods.get(name, config.methods) if name else config.methods
        self.conditioner = Conditioner(methods, sample_rate_hz) if methods.any else None
        self.band: ModelBand | None = None
        self.watch: ModelWatch | None = None
        self.phases: PhaseLog | None = None
        self.aux_windows: AuxWindows | None = None   # the aux samples of each window (model check, phases)

    def suffixed(self, key: str) -> str:
        """``key`` as this axis names it: ``<key>_<axis>``, or ``key`` for a one-axis stream."""
        return f"{key}_{self.name}" if self.name else key

    def named(self, events: Sequence[Event]) -> Sequence[Event]:
        """``events`` of this axis, with their axis set."""
        return [replace(e, axis=self.name) for e in events] if self.name else events

    def start(self, aux_names: tuple[str, ...], source_name: str) -> tuple[str, ...]:
        """Before the first block (``aux_names``: this axis's aux channels): the live
        methods checked, the model check set up; returns the channel names it adds."""
        if self.band is not None:
            self.watch = ModelWatch(self.band, aux_names)
        states = tuple(n for n in STATE_CHANNELS if n in aux_names)
        if states:
            self.phases = PhaseLog()
        if self.watch is not None or self.phases is not None:
            held = aux_names if self.watch is not None else states
            self.aux_pending, self.aux_windows = _AuxFifo(), AuxWindows(held, self.engine.window_n)
        if self.conditioner is None:
            return ()
        self.conditioner.check(aux_names, source_name)
        return tuple(self.suffixed(c) for c in self.conditioner.channels)

    def prepare(self, b: Block, use_ref: bool) -> _Prepared:
        """This axis of block ``b`` (its error against rot_dps when ``use_ref``) through
        the live methods; its aux channels kept for the model check."""
        view = b.axis(self.name) if self.name else b
        if self.aux_windows is not None:
            self.aux_pending.push(view.aux, len(b))
        y = np.ascontiguousarray(view.error_rate_dph if use_ref else view.rate_dph)
        valid = np.ascontiguousarray(view.valid) & np.isfinite(y)
        if self.conditioner is None:
            return _Prepared(y, valid, {}, ())
        c = self.conditioner.push(b.t_s, y, valid, view.aux)
        return _Prepared(c.rate_dph, c.valid, {self.suffixed(k): v for k, v in c.channels.items()},
                         tuple(self.named(c.events)))

    def gate(self, t_s: np.ndarray, y: np.ndarray, valid: np.ndarray,
             dispatch: Callable[[Sequence[Event]], None]) -> tuple[np.ndarray, np.ndarray]:
        """The samples (deg/h) and valid flags to analyse now: with a motion gate, those it
        has judged, platform motion made invalid (its events to ``dispatch``)."""
        if self.motion is None:
            return y, valid
        y, valid, events = self.motion.push(t_s, y, valid)
        dispatch(self.named(events))
        return y, valid

    def analyse(self, y: np.ndarray, valid: np.ndarray) -> DadevResult:
        """The next samples into DAVAR and the whole-run tail; the windows they complete."""
        if self.aux_windows is not None:  # the aux samples of exactly these samples (model check, phases)
            self.aux_windows.push(self.aux_pending.take(len(y)), len(y))
        res = self.engine.push(y, valid)
        self.tail.push(y, valid)
        return res

    def window_checks(self, res: DadevResult, fit: NoiseFit, t_end: np.ndarray) -> list[Event]:
        """Completed windows against the model's band and into the phase log: the
        ``model_band`` events, and a ``phase`` event where a window starts a phase."""
        assert self.aux_windows is not None
        events: list[Event] = []
        coefs = fit.coefficients()   # a DADEV fit: arrays over the windows
        values = {n: np.atleast_1d(c.value) for n, c in coefs.items()}
        known = {n: np.atleast_1d(c.identifiable) for n, c in coefs.items()}
        for i in range(len(res)):
            aux = self.aux_windows.window(int(res.end_index[i]))
            if self.watch is not None:
                events += self.watch.frame(float(t_end[i]), res.adev_dph[i], aux)
            if self.phases is not None:
                started = self.phases.frame(float(t_end[i]), aux, {n: float(v[i]) for n, v in values.items()},
                                            {n: bool(k[i]) for n, k in known.items()})
                if started is not None:
                    events.append(Event(float(t_end[i]), "phase", f"{started.state} (the window ending at "
                                        f"{t_end[i]:.1f} s is the first wholly in it)"))
        return events

    def counters(self) -> dict[str, int]:
        """The live methods' counters."""
        c = {}
        if self.conditioner is not None:
            if self.conditioner.rejector is not None:
                c["outliers_rejected"] = self.conditioner.rejector.rejected
            if self.conditioner.thermal is not None:
                c["samples_without_temperature"] = self.conditioner.no_temperature
        return c

    def overall(self, t_last_s: float, taus: TauSpec) -> None:
        """The whole-run ADEV and fit (of the latest OVERALL_MAX_SAMPLES samples, the last
        at ``t_last_s``) into the summary."""
        from fogmon.davar.batch import oadev
        from fogmon.davar.fit import fit_noise

        summary, sample_rate_hz = self.summary, self.sample_rate_hz
        del self.engine  # its window buffers are not needed for the whole-run ADEV: lower peak memory
        rate, valid = self.tail.take()
        if len(rate) < 8:
            return
        try:
            summary.overall = oadev(rate, sample_rate_hz, taus=taus, valid=valid)
        except FogmonError as e:  # a run shorter than the window can be too short for every tau
            axis = f"axis {self.name}: " if self.name else ""
            warnings.warn(f"{axis}no whole-run Allan deviation: {e}", FogmonWarning, stacklevel=2)
        else:
            summary.overall_first_s = t_last_s - (len(rate) - 1) / sample_rate_hz
            summary.overall_fit = fit_noise(summary.overall)


def run_pipeline(source: Source, config: PipelineConfig, sinks: Sequence[Sink], pacer: Pacer | None = None) -> Summary:
    """Stream ``source`` through DAVAR and the noise fit into ``sinks`` (Pipeline)."""
    return Pipeline(source, config, pacer).run(sinks)


class _AuxFifo:
    """Aux samples delivered but not yet analysed (the motion gate holds samples back):
    ``take(n)`` gives the next ``n`` samples of every channel, in order."""

    def __init__(self) -> None:
        self._parts: deque[tuple[dict[str, np.ndarray], int]] = deque()

    def push(self, aux: dict[str, np.ndarray], n: int) -> None:
        if n:
            self._parts.append((aux, n))

    def take(self, n: int) -> dict[str, np.ndarray]:
        got: dict[str, list[np.ndarray]] = {}
        while n > 0 and self._parts:
            aux, k = self._parts[0]
            use = min(n, k)
            for name, a in aux.items():
                got.setdefault(name, []).append(a[:use])
            if use == k:
                self._parts.popleft()
            else:
                self._parts[0] = ({name: a[use:] for name, a in aux.items()}, k - use)
            n -= use
        return {name: np.concatenate(parts) for name, parts in got.items()}


class _Tail:
    """The latest ``n_max`` samples and valid flags, for the whole-run ADEV: a ring buffer
    of fixed size holding copies (no block is kept alive; pages not yet written cost no
    memory)."""

    def __init__(self, n_max: int):
        self.n_max = n_max
        self._rate = np.empty(n_max)
        self._valid = np.empty(n_max, bool)
        self._total = 0  # samples pushed so far

    def push(self, rate: np.ndarray, valid: np.ndarray) -> None:
        skip = max(len(rate) - self.n_max, 0)
        self._total += skip
        for src, buf in ((rate[skip:], self._rate), (valid[skip:], self._valid)):
            at = self._total % self.n_max
            first = min(len(src), self.n_max - at)
            buf[at:at + first] = src[:first]
            buf[:len(src) - first] = src[first:]
        self._total += len(rate) - skip

    def take(self) -> tuple[np.ndarray, np.ndarray]:
        """(rate, valid) of the latest min(pushed, n_max) samples, oldest first; the
        buffer is released (the tail is done)."""
        n, at = min(self._total, self.n_max), self._total % self.n_max
        if self._total <= self.n_max:
            out = self._rate[:n].copy(), self._valid[:n].copy()
        else:
            out = (np.concatenate([self._rate[at:], self._rate[:at]]),
                   np.concatenate([self._valid[at:], self._valid[:at]]))
        self._rate, self._valid = np.empty(0), np.empty(0, bool)
        return out


def live_samples(duration_s: float, sample_rate_hz: float) -> int:
    """Samples of a live run of ``duration_s`` s from its first sample: those with
    t - t_first <= duration_s - half a sample period (the replay cut, too)."""
    return max(1, math.floor(duration_s * sample_rate_hz - 0.5 + 1e-9) + 1)


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


@dataclass
class _Dropped:
    """Consecutive blocks of a live source dropped from the reader's queue: their span on
    the sample grid (``n`` samples from ``t0_s``) and the first of their events."""

    t0_s: float
    n: int
    blocks: int
    events: list[Event]
    events_left_out: int = 0


class _ThreadedBlocks:
    """Iterate a source's blocks in a reader thread through a queue holding at most
    ``max_samples`` samples (a block alone may be longer), so DAVAR, fits and Rerun never
    keep a device unread and memory stays bounded.

    A source that can wait (a simulation, a file) is held back while the queue is full:
    back-pressure. A live device (LiveSource, ``wait=False``) never is, since an OS serial
    buffer holds ~0.1 s of a 1 kHz KVH: when the pipeline is more than ``max_samples``
    behind, the blocks read meanwhile are dropped, counted (``blocks_dropped``,
    ``samples_dropped`` in ``counters``) and come out as invalid placeholders on the
    same grid with a ``dropped`` event, so the time base holds and nothing is lost
    silently (the raw capture of an archive, written by the device thread, keeps them).
    ``backlog()`` after ``source.close()`` takes what is left once the reader is done."""

    _DONE = object()

    def __init__(self, source: Source, max_samples: int = QUEUE_MAX_SAMPLES, wait: bool | None = None):
        self._source = source
        self.max_samples = max_samples
        self.wait = not isinstance(source, LiveSource) if wait is None else wait
        self.counters = {} if self.wait else {"blocks_dropped": 0, "samples_dropped": 0}
        self._aux_names: tuple[str, ...] = ()  # of the blocks read, for placeholders
        self._axes: tuple[str, ...] = ()
        self.held_back = 0  # times the reader waited for room (back-pressure)
        self._items: deque = deque()
        self._n = 0  # samples in the queue
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._read, name="fogmon-source-reader", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            for b in self._source.blocks():
                if not self._put(b):
                    return
        except BaseException as e:  # handed to the consumer thread
            self._append(e, 0)
        finally:
            self._append(self._DONE, 0)

    def _put(self, b: Block) -> bool:
        """Queue ``b``, waiting for room or dropping it; False once a source that waits is
        closed (nothing more of it is needed). A live device's blocks are queued even after
        the stop: they were read and archived, so ``backlog()`` hands them on to be counted."""
        with self._cond:
            if self._n and self._n + len(b) > self.max_samples:
                if not self.wait:
                    self._drop(b)
                    return True
                self.held_back += 1
                self._cond.notify_all()
                while self._n and self._n + len(b) > self.max_samples and not self._closed:
                    self._cond.wait()
            if self._closed and self.wait:
                return False
            self._aux_names, self._axes = tuple(b.aux), b.axes
        self._append(b, len(b))
        return True

    def _append(self, item, n: int) -> None:
        with self._cond:
            self._items.append(item)
            self._n += n
            self._cond.notify_all()

    def _drop(self, b: Block) -> None:
        self.counters["blocks_dropped"] += 1
        self.counters["samples_dropped"] += len(b)
        rate = float(self._source.sample_rate_hz)
        last = self._items[-1] if self._items else None
        if not (isinstance(last, _Dropped) and abs(last.t0_s + last.n / rate - float(b.t_s[0])) < 0.5 / rate):
            last = _Dropped(float(b.t_s[0]), 0, 0, [])
            self._items.append(last)
        last.n += len(b)
        last.blocks += 1
        room = DROPPED_EVENTS_KEPT - len(last.events)
        last.events += b.events[:room]
        last.events_left_out += max(len(b.events) - room, 0)
        self._cond.notify_all()

    def __iter__(self):
        while True:
            with self._cond:
                while not self._items:
                    self._cond.wait(0.25)  # wakes for Ctrl-C in the main thread
                item = self._items.popleft()
                if isinstance(item, Block):
                    self._n -= len(item)
                    self._cond.notify_all()
            if item is self._DONE:
                return
            if isinstance(item, BaseException):
                raise item
            if isinstance(item, _Dropped):
                yield from self._placeholders(item)
            else:
                yield item

    def _placeholders(self, d: _Dropped):
        rate = float(self._source.sample_rate_hz)
        msg = (f"{d.n} samples ({d.blocks} blocks) from t={d.t0_s:.6f} s dropped: processing fell more than "
               f"{self.max_samples} samples ({self.max_samples / rate:g} s) behind the device"
               + (f"; {d.events_left_out} more events of these blocks only counted" if d.events_left_out else ""))
        events = (Event(d.t0_s, "dropped", msg), *d.events)
        for i in range(0, d.n, PLACEHOLDER_BLOCK):
            m = min(PLACEHOLDER_BLOCK, d.n - i)
            nan = np.full(m, np.nan)
            shape = (m, len(self._axes)) if self._axes else m
            yield Block(d.t0_s + np.arange(i, i + m) / rate, np.full(shape, np.nan), np.zeros(shape, bool),
                        {k: nan for k in self._aux_names}, events if i == 0 else (), self._axes)

    def backlog(self, timeout_s: float = 10.0) -> list[Block]:
        """After ``source.close()``: the blocks not yet taken, in order, up to the source's
        end (at most ``timeout_s`` s of waiting for it; a reader held back by a full queue
        is released and stops); an error after the stop is dropped."""
        out: list[Block] = []
        deadline = time.monotonic() + timeout_s
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        while time.monotonic() < deadline:
            with self._cond:
                if not self._items:
                    if not self._thread.is_alive():
                        break
                    self._cond.wait(0.05)
                    continue
                item = self._items.popleft()
            if item is self._DONE:
                break
            if isinstance(item, _Dropped):
                out += self._placeholders(item)
            elif isinstance(item, Block) and (len(item) or item.events):
                out.append(item)
        return out


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
