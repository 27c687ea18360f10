"""The analysis of one axis of a run (``AxisAnalysis``): live methods, motion gate,
streaming DAVAR, coefficient-jump events, model check and phases, and the buffers it keeps
(the aux samples the motion gate holds back, the tail for the whole-run ADEV).
"""
from __future__ import annotations

import warnings
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from fogmon.block import Block, Event
from fogmon.davar.fit import NoiseFit
from fogmon.davar.jumps import JumpDetector
from fogmon.davar.result import DadevResult
from fogmon.errors import FogmonError, FogmonWarning
from fogmon.methods.live import Conditioner
from fogmon.modelcheck import AuxWindows, ModelBand, ModelWatch
from fogmon.phases import STATE_CHANNELS, PhaseLog
from fogmon.pipeline.config import PipelineConfig, TauSpec
from fogmon.sinks.base import AxisSummary

#: The whole-run ADEV of the console summary keeps at most this many samples (the latest).
OVERALL_MAX_SAMPLES = 2**22


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
        from fogmon.motion_gate import MotionGate

        self.name, self.summary, self.sample_rate_hz = name, summary, sample_rate_hz
        self.engine = StreamingDadev(sample_rate_hz, window_s, taus=config.taus, hop_s=hop_s)  # checks taus
        self.jumps = JumpDetector(window_s)
        self.tail = _Tail(OVERALL_MAX_SAMPLES)
        self.motion = None if config.keep_motion else MotionGate(sample_rate_hz)
        methods = config.axis_methods.get(name, config.methods) if name else config.methods
        self.conditioner = Conditioner(methods, sample_rate_hz) if methods.any else None
        self.band: ModelBand | None = None
        self.watch: ModelWatch | None = None
        self.phases: PhaseLog | None = None
        self.aux_windows: AuxWindows | None = None   # the aux samples of each window (model check, phases)
        self.moving = np.zeros(0, dtype=bool)   # of the samples last released: kept out as platform motion

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
             dispatch: Callable[[Sequence[Event]], None]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The samples (deg/h), valid flags and platform-motion flags (None: no gate) to
        analyse now: with a motion gate, those it has judged, platform motion made invalid
        (its events to ``dispatch``); ``moving`` marks those the gate made invalid (the
        accelerometers of the axis follow it)."""
        if self.motion is None:
            self.moving = np.zeros(len(y), dtype=bool)
            return y, valid, None
        out = self.motion.push(t_s, y, valid)
        self.moving = out.moved
        dispatch(self.named(out.events))
        return out.rate_dph, out.valid, out.moved

    def flush_gate(self, dispatch: Callable[[Sequence[Event]], None]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At the end of the run: what the motion gate still holds (as ``gate``), and its
        spans into the summary."""
        assert self.motion is not None
        out = self.motion.flush()
        self.moving = out.moved
        dispatch(self.named(out.events))
        self.summary.motion_spans, self.summary.motion_samples = list(self.motion.spans), self.motion.samples_excluded
        return out.rate_dph, out.valid, out.moved

    def analyse(self, y: np.ndarray, valid: np.ndarray, moved: np.ndarray | None = None) -> DadevResult:
        """The next samples into DAVAR and the whole-run tail (``moved``: the samples
        the motion gate made invalid, for the fit with them); the windows they complete."""
        if self.aux_windows is not None:  # the aux samples of exactly these samples (model check, phases)
            self.aux_windows.push(self.aux_pending.take(len(y)), len(y))
        res = self.engine.push(y, valid)
        self.tail.push(y, valid, moved)
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
        """The whole-run ADEV and fit (``whole_record_fit`` of the latest
        OVERALL_MAX_SAMPLES samples, the last at ``t_last_s``) into the summary; when the
        motion gate kept samples of them out, also the fit with those samples in
        (``fit_with_motion``)."""
        from fogmon.davar.record import whole_record_fit

        summary, sample_rate_hz = self.summary, self.sample_rate_hz
        del self.engine  # its window buffers are not needed for the whole-run ADEV: lower peak memory
        rate, valid, moved = self.tail.take()
        if len(rate) < 8:
            return
        try:
            summary.overall, summary.overall_fit = whole_record_fit(rate, valid, sample_rate_hz, taus)
        except FogmonError as e:  # a run shorter than the window can be too short for every tau
            axis = f"axis {self.name}: " if self.name else ""
            warnings.warn(f"{axis}no whole-run Allan deviation: {e.message}", FogmonWarning, stacklevel=2)
            return
        summary.overall_first_s = t_last_s - (len(rate) - 1) / sample_rate_hz
        if moved.any():
            summary.motion_in_tail = int(np.count_nonzero(moved))
            summary.fit_with_motion = whole_record_fit(rate, valid | moved, sample_rate_hz, taus)[1]


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
    """The latest ``n_max`` samples, valid flags and platform-motion flags (the samples
    the motion gate made invalid), for the whole-run ADEV: ring buffers of fixed size
    holding copies (no block is kept alive; pages not yet written cost no memory)."""

    def __init__(self, n_max: int):
        self.n_max = n_max
        self._rate = np.empty(n_max)
        self._valid = np.empty(n_max, bool)
        self._moved = np.empty(n_max, bool)
        self._total = 0  # samples pushed so far

    def push(self, rate: np.ndarray, valid: np.ndarray, moved: np.ndarray | None = None) -> None:
        skip = max(len(rate) - self.n_max, 0)
        self._total += skip
        moved = np.zeros(len(rate), bool) if moved is None else moved
        for src, buf in ((rate[skip:], self._rate), (valid[skip:], self._valid), (moved[skip:], self._moved)):
            at = self._total % self.n_max
            first = min(len(src), self.n_max - at)
            buf[at:at + first] = src[:first]
            buf[:len(src) - first] = src[first:]
        self._total += len(rate) - skip

    def take(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rate, valid, moved) of the latest min(pushed, n_max) samples, oldest first;
        the buffers are released (the tail is done)."""
        n, at = min(self._total, self.n_max), self._total % self.n_max
        bufs = (self._rate, self._valid, self._moved)
        if self._total <= self.n_max:
            rate, valid, moved = (b[:n].copy() for b in bufs)
        else:
            rate, valid, moved = (np.concatenate([b[at:], b[:at]]) for b in bufs)
        self._rate, self._valid, self._moved = np.empty(0), np.empty(0, bool), np.empty(0, bool)
        return rate, valid, moved
