"""The streaming pipeline shared by `fogmon replay` and `fogmon monitor`:
source -> StreamingDadev (ring-buffer DAVAR) -> fit_noise per completed window -> sinks.

A live gyro and a replay differ only in the source. Blocks are processed as they come
(Python overhead per block, not per sample); every completed window (one per hop) is
fitted with the IEEE-952 model and handed to the sinks with its recording time; the run
ends at the end of the source, at ``--duration-s`` of recording time, or on Ctrl-C
(SIGTERM, SIGHUP: fogmon.stopping), and always closes the source and the sinks so the
.rrd and the archive are complete. With ``--rotate-s`` blocks are cut where a new piece
of the outputs begins and the sinks are told (``Sink.rotate``) before its first block.
"""
from __future__ import annotations

import argparse
import math
import sys
import threading
import time
import warnings
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from fogmon import stopping
from fogmon.block import Block, Event
from fogmon.cli.values import number, positive
from fogmon.davar.jumps import JumpDetector
from fogmon.davar.taus import MAX_PER_DECADE, check_per_decade
from fogmon.errors import FogmonError, FogmonWarning

#: IEEE-952 coefficients in the order they are shown, with their units.
COEFFICIENTS = {"Q_arcsec": "arcsec", "N_dpsh": "deg/sqrt(h)", "B_dph": "deg/h",
                "K_dphsh": "deg/h/sqrt(h)", "R_dphh": "deg/h^2"}
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


# ----------------------------------------------------------------------------- options
def add_pipeline_arguments(parser: argparse.ArgumentParser, replay: bool = True) -> None:
    """Options of `fogmon replay` and `fogmon monitor` (``replay=False``: no --realtime):
    engine, sinks, pacing."""
    g = parser.add_argument_group("dynamic Allan deviation (DAVAR)")
    g.add_argument("--window-s", type=positive, metavar="W",
                   help="window length in s. Default: replay: a quarter of the recording (of its first "
                        "--duration-s s) rounded down to a power of two of samples, within "
                        f"{MIN_WINDOW_SAMPLES}..{MAX_WINDOW_SAMPLES} samples; live: {LIVE_WINDOW_SAMPLES} samples "
                        "(65.5 s at 1 kHz, 655.4 s at 100 Hz), or that rule applied to --duration-s when it "
                        "gives a shorter window")
    g.add_argument("--hop-s", type=positive, metavar="H",
                   help="a new ADEV + noise fit every H s of recording time, at most the window "
                        "(default: window/8)")
    g.add_argument("--raw-rate", action="store_true",
                   help="analyse rate_dph as recorded even when the recording has rot_dps; by default "
                        "DAVAR and the fits see the gyro's error rate_dph - 3600 x rot_dps (deg/h) "
                        "against the reference rotation")
    g.add_argument("--keep-motion", action="store_true",
                   help="analyse platform motion too: by default stretches where the rate moves far beyond "
                        "the sensor's noise with no rot_dps to say why (a turntable, a vehicle, a person) "
                        "are kept out of DAVAR and the fits, with platform_motion events (docs/motion.md)")
    g.add_argument("--taus", default="octave", type=parse_taus, metavar="T",
                   help="averaging times: octave (default), decade, all, an integer N = "
                        f"1..{MAX_PER_DECADE} (N log-spaced per decade), or tau values in s written with a "
                        "decimal point or comma-separated (1000.0 = one tau of 1000 s; 0.1,1,10). Only "
                        "one sample <= tau <= window/4 can be computed: other values are left out with a "
                        "warning")
    o = parser.add_argument_group("output (Rerun)")
    o.add_argument("--rrd", metavar="OUT.rrd", help="write a Rerun recording file (headless); "
                   "open it with `rerun OUT.rrd`")
    o.add_argument("--connect", metavar="URL", nargs="?", const="rerun+http://127.0.0.1:9876/proxy",
                   help="stream to a running Rerun viewer (default URL rerun+http://127.0.0.1:9876/proxy; "
                        "start one with `rerun`)")
    o.add_argument("--serve", action="store_true",
                   help="host a Rerun gRPC server that viewers connect to (`rerun URL` as printed); "
                        "keeps serving after a replay until Ctrl-C")
    o.add_argument("--bind", default="127.0.0.1", metavar="ADDR",
                   help="address --serve listens on (default 127.0.0.1, this machine only; 0.0.0.0 for all)")
    o.add_argument("--port", type=number(1, 65535, integer=True), default=9876, help="port --serve listens on, 1..65535 (default 9876)")
    o.add_argument("--rotate-s", type=_rotate_s, metavar="S", default=None if replay else 3600.0,
                   help=("write the .rrd as pieces OUT-0001.rrd, OUT-0002.rrd, ... of S s of recording time "
                         "each (default: one file)" if replay else
                         "start new output files every S s of recording time: the archive's samples-NNNN.csv "
                         "and raw capture pieces, and the .rrd as OUT-NNNN.rrd (default 3600 = hourly; "
                         "0 = one piece)"))
    o.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    o.add_argument("--quiet", action="store_true", help="no console summary at the end")
    p = parser.add_argument_group("pacing")
    if "--duration-s" not in parser._option_string_actions:  # the source options may define it
        p.add_argument("--duration-s", type=positive, metavar="S",
                       help="stop after S s of recording time")
    if replay and "--realtime" not in parser._option_string_actions:
        p.add_argument("--realtime", nargs="?", const=1.0, type=positive, metavar="X",
                       help="pace a replay at X times real time (default X = 1 when given; "
                            "without --realtime a replay runs as fast as it can)")


def _rotate_s(text: str) -> float | None:
    """``--rotate-s``: S > 0, or 0 for no rotation (None)."""
    try:
        if float(text) == 0:
            return None
    except ValueError:
        pass
    return positive(text)


def parse_taus(text: str):
    """``--taus`` value -> what ``tau_grid`` takes: a grid name, an int per decade
    (1..MAX_PER_DECADE), or a tau_s array (values with a decimal point or comma-separated)."""
    s = text.strip().lower()
    if s in ("octave", "decade", "all"):
        return s
    if s.isdigit():
        try:
            return check_per_decade(int(s))
        except FogmonError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    try:
        tau_s = np.array([float(x) for x in s.split(",")], dtype=np.float64)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected octave, decade, all, an integer per decade or tau values in s, got {text!r}") from None
    if not np.all(np.isfinite(tau_s) & (tau_s > 0)):
        raise argparse.ArgumentTypeError(f"tau values must be finite and > 0 s, got {text!r}")
    return tau_s


def default_window_s(rate_hz: float, n_samples: int | None) -> float:
    """Default window in s: for a record of ``n_samples`` a quarter of it rounded down to a
    power of two of samples (within MIN..MAX_WINDOW_SAMPLES, never longer than the record);
    live (``n_samples`` None) LIVE_WINDOW_SAMPLES."""
    if n_samples is None:
        return LIVE_WINDOW_SAMPLES / rate_hz
    quarter = max(n_samples // 4, 1)
    n = 2 ** int(math.floor(math.log2(quarter)))
    n = min(max(n, MIN_WINDOW_SAMPLES), MAX_WINDOW_SAMPLES, n_samples)
    return n / rate_hz


def window_and_hop(args: argparse.Namespace, rate_hz: float, total_n: int | None) -> tuple[float, float]:
    """Window and hop (s) from ``--window-s``/``--hop-s`` or their defaults, checked
    against the sample rate and the samples the run will have (the record's ``total_n``,
    None when live, cut to ``--duration-s``); FogmonError naming the option otherwise."""
    duration_s = getattr(args, "duration_s", None)
    n_run = total_n
    if duration_s is not None:
        n_cut = round(duration_s * rate_hz)
        if n_cut < 1:
            raise FogmonError(f"--duration-s {duration_s:g} s is shorter than one sample at {rate_hz:g} Hz")
        n_run = n_cut if total_n is None else min(total_n, n_cut)
    if n_run is not None and n_run < 8:
        what = "the recording has" if n_run == total_n else "--duration-s leaves"
        raise FogmonError(f"{what} {n_run} samples at {rate_hz:g} Hz: an Allan deviation needs at least 8")
    window_s = getattr(args, "window_s", None)
    if window_s is None:
        window_s = default_window_s(rate_hz, n_run)
        if total_n is None:  # live: the live window unless --duration-s asks for a shorter run
            window_s = min(window_s, default_window_s(rate_hz, None))
    if n_run is not None and window_s * rate_hz > n_run:
        what = "the recording" if n_run == total_n else "the --duration-s run"
        raise FogmonError(f"--window-s {window_s:g} s is longer than {what} "
                          f"({n_run / rate_hz:g} s = {n_run} samples)")
    if window_s * rate_hz < 8:
        raise FogmonError(f"--window-s {window_s:g} s holds fewer than 8 samples at {rate_hz:g} Hz")
    hop_s = getattr(args, "hop_s", None) or window_s / 8
    if hop_s * rate_hz < 1:
        raise FogmonError(f"--hop-s {hop_s:g} s is shorter than one sample at {rate_hz:g} Hz")
    if hop_s > window_s:
        raise FogmonError(f"--hop-s {hop_s:g} s is longer than the window ({window_s:g} s): the samples "
                          f"between windows would never be analysed")
    return window_s, hop_s


# ----------------------------------------------------------------------------- sinks
@dataclass(frozen=True)
class StreamInfo:
    """What sinks learn before the first block: source, sample rate (Hz), window/hop (s),
    taus (s), auxiliary channel names."""

    source_name: str
    rate_hz: float
    window_s: float
    hop_s: float
    tau_s: np.ndarray
    aux_names: tuple[str, ...]
    #: what DAVAR analyses: "rate_dph", or "rate_dph - 3600 x rot_dps" (error vs reference rotation)
    analysed: str = "rate_dph"


class Sink:
    """Receives the pipeline's outputs; every method is optional (no-op here). Sinks
    finish in increasing ``finish_order`` (the console last, so it can name the files)."""

    finish_order = 0

    def start(self, info: StreamInfo) -> None: ...

    def block(self, block: Block) -> None: ...

    def frames(self, dadev, fit, t_end_s: np.ndarray) -> None:
        """Completed windows: a DadevResult (T rows), its NoiseFit (arrays over T) and the
        recording time (s) of each window's last sample."""

    def events(self, events: Sequence[Event]) -> None: ...

    def rotate(self, piece: int, t_s: float) -> None:
        """Piece ``piece`` (from 1) of the outputs begins with the next block, at recording
        time ``t_s`` (--rotate-s)."""

    def source_counters(self, t_s: float, counters: dict[str, int]) -> None: ...

    def finish(self, summary: "Summary") -> None: ...


@dataclass
class Summary:
    """The end-of-run account: what was processed, the whole-run ADEV and fit, counters."""

    source_name: str
    rate_hz: float
    window_s: float
    hop_s: float
    n_samples: int = 0
    n_invalid: int = 0
    t_first_s: float = math.nan
    t_last_s: float = math.nan
    n_windows: int = 0
    wall_s: float = 0.0
    source_wall_s: float = 0.0    # wall time from opening the source to the end of the run, s
    interrupted: bool = False
    analysed: str = "rate_dph"    # what DAVAR analysed (see StreamInfo.analysed)
    failed: bool = False          # stopped by an error (reported by the caller, no summary)
    overall: object = None        # AdevResult of the whole run (the latest OVERALL_MAX_SAMPLES)
    overall_fit: object = None    # NoiseFit of ``overall``
    overall_first_s: float = math.nan
    counters: dict[str, int] = field(default_factory=dict)
    event_counts: dict[str, int] = field(default_factory=dict)
    outputs: list[str] = field(default_factory=list)
    motion_spans: list = field(default_factory=list)   # MotionSpan: kept out of DAVAR and the fits
    motion_samples: int = 0       # valid samples the motion gate made invalid

    @property
    def duration_s(self) -> float:
        """Recording time covered, s."""
        return (self.t_last_s - self.t_first_s + 1.0 / self.rate_hz) if self.n_samples else 0.0

    @property
    def speed_x(self) -> float:
        """Recording time / wall time."""
        return self.duration_s / self.wall_s if self.wall_s > 0 else math.inf


# ----------------------------------------------------------------------------- helpers
def slice_block(b: Block, start: int, stop: int) -> Block:
    """Samples ``start:stop`` of a block, with the events that fall in their time span
    (the first slice also takes events before it, the last those after it)."""
    n = len(b)
    t0 = b.t_s[start] if start > 0 else -math.inf
    t1 = b.t_s[stop] if stop < n else math.inf
    ev = tuple(e for e in b.events if t0 <= e.t_s < t1)
    return Block(b.t_s[start:stop], b.rate_dph[start:stop], b.valid[start:stop],
                 {k: v[start:stop] for k, v in b.aux.items()}, ev)


# ----------------------------------------------------------------------------- run
def run_pipeline(source, args: argparse.Namespace, extra_sinks: Iterable[Sink] = (),
                 sinks: Sequence[Sink] | None = None) -> Summary:
    """Stream ``source`` through DAVAR and the noise fit into the sinks named by ``args``
    (``--rrd``/``--connect``/``--serve`` and the console summary) plus ``extra_sinks``.
    ``sinks`` replaces the sinks built from ``args`` (tests, notebooks). Returns the
    Summary; the source and all sinks are closed whatever happens."""
    from fogmon.davar.batch import oadev
    from fogmon.davar.fit import fit_noise
    from fogmon.davar.streaming import StreamingDadev
    from fogmon.davar.taus import tau_grid
    from fogmon.motion import MotionGate
    from fogmon.sinks.console import ReplayProgress

    rate_hz = float(source.rate_hz)
    total_n = record_samples(source)
    window_s, hop_s = window_and_hop(args, rate_hz, total_n)
    taus = getattr(args, "taus", "octave")
    rotate_s = getattr(args, "rotate_s", None)
    piece_n = int(round(rotate_s * rate_hz)) if rotate_s else None
    if piece_n is not None and piece_n < 1:
        raise FogmonError(f"--rotate-s {rotate_s:g} s is shorter than one sample at {rate_hz:g} Hz")
    piece = 1
    engine = StreamingDadev(rate_hz, window_s, taus=taus, hop_s=hop_s)
    if sinks is None:
        sinks = build_sinks(args)
    sinks = [*sinks, *extra_sinks]
    summary = Summary(source.name, rate_hz, window_s, hop_s)
    jumps = JumpDetector(window_s)
    duration_s = getattr(args, "duration_s", None)
    realtime = getattr(args, "realtime", None)
    progress = ReplayProgress(min(total_n / rate_hz, duration_s or math.inf) if total_n else 0.0,
                              enabled=not getattr(args, "no_progress", False) and sys.stderr.isatty()
                              and (realtime is None or realtime > 1))
    tail = _Tail(OVERALL_MAX_SAMPLES)
    event_counts: Counter = Counter()
    started = False
    wall0 = wall_start = time.monotonic()
    t_origin = None
    done = False
    use_ref = False
    reader = None
    motion = None if getattr(args, "keep_motion", False) else MotionGate(rate_hz)

    def analyse(y: np.ndarray, valid: np.ndarray) -> None:
        """DAVAR, fits, jump events and the whole-run tail for the next samples."""
        res = engine.push(y, valid)
        if len(res):
            fit = fit_noise(res)
            t_end = t_origin + np.asarray(res.end_index, dtype=np.float64) / rate_hz
            for s in sinks:
                s.frames(res, fit, t_end)
            summary.n_windows += len(res)
            _dispatch_events(sinks, jumps.update(fit, t_end), event_counts)
            counters = _counters(source, reader)
            for s in sinks:
                s.source_counters(float(t_end[-1]), counters)
        tail.push(y, valid)

    try:
        if total_n is None:  # live: compile before the device is opened, then read it in a thread
            _warm_up(rate_hz, window_s, hop_s, taus)
            if duration_s is not None and hasattr(source, "limit"):
                source.limit(live_samples(duration_s, rate_hz))  # nothing after the cut is read
            reader = _ThreadedBlocks(source)
        wall_start = time.monotonic()
        wall_limit = None if duration_s is None or total_n is not None else \
            duration_s + max(LIVE_WALL_SLACK_S, 0.1 * duration_s)
        for big in (reader if reader is not None else source.blocks()):
            opened = getattr(source, "opened_s", None) or wall_start
            if wall_limit is not None and time.monotonic() > opened + wall_limit:
                source.close()  # a live source that stalls still stops on time; what it read is kept
                wall_limit = None
            if not len(big):
                _dispatch_events(sinks, big.events, event_counts)
                continue
            if t_origin is None:
                t_origin = float(big.t_s[0])
            if duration_s is not None:
                stop = int(np.searchsorted(big.t_s, t_origin + duration_s - 0.5 / rate_hz, side="right"))
                if stop < len(big):
                    big, done = slice_block(big, 0, stop), True
                    if not stop:
                        break
            for b_piece, b in _at_seams(_paced(big, realtime, rate_hz), t_origin, rate_hz, piece_n):
                if realtime:
                    _sleep_until(wall0 + (float(b.t_s[-1]) - t_origin) / realtime)
                with stopping.shielded():  # a block reaches every sink, or none: stop between blocks
                    if not started:
                        m = tau_grid(rate_hz, int(round(window_s * rate_hz)), taus)
                        use_ref = "rot_dps" in b.aux and not getattr(args, "raw_rate", False)
                        summary.analysed = ERROR_EXPR if use_ref else "rate_dph"
                        info = StreamInfo(source.name, rate_hz, window_s, hop_s, m / rate_hz, tuple(b.aux),
                                          summary.analysed)
                        for s in sinks:
                            s.start(info)
                        started = True
                        summary.t_first_s = float(b.t_s[0])
                    piece = _deliver(b, b_piece, piece, sinks, summary, event_counts)
                    y = b.error_rate_dph if use_ref else b.rate_dph
                    analyse(*_gate_motion(motion, b.t_s, y, b.valid & np.isfinite(y), sinks, event_counts))
                    progress.update(summary.duration_s, time.monotonic() - wall0)
            if done:
                break
    except KeyboardInterrupt:
        summary.interrupted = True
    except BaseException:
        summary.failed = True
        raise
    finally:
        stopping.closing()  # a further Ctrl-C/SIGTERM must not cut the outputs short
        progress.update(summary.duration_s, time.monotonic() - wall0)
        progress.close()
        source.close()
        if reader is not None:
            backlog = reader.backlog()
            if started and not summary.failed and not done:  # read before the stop: archived, not analysed
                for big in backlog:
                    if not len(big):
                        _dispatch_events(sinks, big.events, event_counts)
                        continue
                    for b_piece, b in _at_seams([big], t_origin, rate_hz, piece_n):
                        piece = _deliver(b, b_piece, piece, sinks, summary, event_counts)
        if motion is not None and started and not summary.failed:   # the samples the gate still holds
            y, valid, ev = motion.flush()
            _dispatch_events(sinks, ev, event_counts)
            analyse(y, valid)
            summary.motion_spans, summary.motion_samples = list(motion.spans), motion.samples_excluded
        summary.wall_s = time.monotonic() - wall0
        summary.source_wall_s = time.monotonic() - wall_start
        summary.counters = _counters(source, reader)
        summary.event_counts = dict(event_counts)
        try:
            del engine  # its window buffers are not needed for the whole-run ADEV: lower peak memory
            rate, valid = tail.take()
            if len(rate) >= 8:
                try:
                    summary.overall = oadev(rate, rate_hz, taus=taus, valid=valid)
                except FogmonError as e:  # a run shorter than the window can be too short for every tau
                    warnings.warn(f"no whole-run Allan deviation: {e}", FogmonWarning)
                else:
                    summary.overall_first_s = summary.t_last_s - (len(rate) - 1) / rate_hz
                    summary.overall_fit = fit_noise(summary.overall)
        finally:
            for s in sorted(sinks, key=lambda k: getattr(k, "finish_order", 0)):
                s.finish(summary)
    return summary


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
        self._rate = self._valid = None
        return out


def _counters(source, reader: "_ThreadedBlocks | None") -> dict[str, int]:
    """The source's counters and the reader's (dropped blocks)."""
    return {**(getattr(source, "counters", {}) or {}), **(reader.counters if reader is not None else {})}


def _deliver(b: Block, b_piece: int, piece: int, sinks, summary: Summary, event_counts: Counter) -> int:
    """Hand a block to the sinks (after ``rotate`` when it begins piece ``b_piece``) and
    count it in the summary; returns the current piece."""
    if b_piece != piece:
        for s in sinks:
            s.rotate(b_piece, float(b.t_s[0]))
    if len(b):
        summary.n_samples += len(b)
        summary.n_invalid += int(len(b) - np.count_nonzero(b.valid))
        summary.t_last_s = float(b.t_s[-1])
        for s in sinks:
            s.block(b)
    _dispatch_events(sinks, b.events, event_counts)
    return b_piece


def live_samples(duration_s: float, rate_hz: float) -> int:
    """Samples of a live run of ``duration_s`` s from its first sample: those with
    t - t_first <= duration_s - half a sample period (the replay cut, too)."""
    return max(1, math.floor(duration_s * rate_hz - 0.5 + 1e-9) + 1)


def record_samples(source) -> int | None:
    """Length in samples of a finite source (a replay), None for a live one."""
    return getattr(source, "n_samples", None)


def _warm_up(rate_hz: float, window_s: float, hop_s: float, taus) -> None:
    """Compile/load the engine's kernels on a throw-away instance before the source is
    opened, so a live device is not left unread while they compile."""
    from fogmon.davar.fit import fit_noise
    from fogmon.davar.streaming import StreamingDadev

    n = int(round(window_s * rate_hz)) + int(round(hop_s * rate_hz))
    if n > 1 << 22:
        return
    res = StreamingDadev(rate_hz, window_s, taus=taus, hop_s=hop_s).push(
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

    def __init__(self, source, max_samples: int = QUEUE_MAX_SAMPLES, wait: bool | None = None):
        from fogmon.sources.live import LiveSource

        self._source = source
        self.max_samples = max_samples
        self.wait = not isinstance(source, LiveSource) if wait is None else wait
        self.counters = {} if self.wait else {"blocks_dropped": 0, "samples_dropped": 0}
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
        rate = float(self._source.rate_hz)
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
        rate = float(self._source.rate_hz)
        msg = (f"{d.n} samples ({d.blocks} blocks) from t={d.t0_s:.6f} s dropped: processing fell more than "
               f"{self.max_samples} samples ({self.max_samples / rate:g} s) behind the device"
               + (f"; {d.events_left_out} more events of these blocks only counted" if d.events_left_out else ""))
        events = (Event(d.t0_s, "dropped", msg), *d.events)
        for i in range(0, d.n, PLACEHOLDER_BLOCK):
            m = min(PLACEHOLDER_BLOCK, d.n - i)
            nan = np.full(m, np.nan)
            yield Block(d.t0_s + np.arange(i, i + m) / rate, nan, np.zeros(m, bool),
                        {k: nan for k in getattr(self._source, "aux_names", ())}, events if i == 0 else ())

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


def _gate_motion(motion: "MotionGate | None", t_s: np.ndarray, y: np.ndarray, valid: np.ndarray, sinks,
                 counts: Counter) -> tuple[np.ndarray, np.ndarray]:
    """The samples (deg/h) and valid flags to analyse now: with a motion gate, those it
    has judged, platform motion made invalid (its events dispatched)."""
    if motion is None:
        return y, valid
    y, valid, events = motion.push(t_s, y, valid)
    _dispatch_events(sinks, events, counts)
    return y, valid


def _dispatch_events(sinks, events, counts: Counter) -> None:
    if not events:
        return
    counts.update(e.kind for e in events)
    for s in sinks:
        s.events(events)


def _paced(b: Block, realtime: float | None, rate_hz: float):
    """Split a block into pieces of <= 0.1 s of wall time when pacing, else pass it on."""
    if not realtime:
        yield b
        return
    step = max(1, int(0.1 * realtime * rate_hz))
    for i in range(0, len(b), step):
        yield slice_block(b, i, min(i + step, len(b)))


def _at_seams(blocks: Iterable[Block], t_origin: float, rate_hz: float, piece_n: int | None):
    """(piece, block) pairs, blocks cut where a new piece of ``piece_n`` samples begins
    (piece 1 starts at ``t_origin``; ``piece_n`` None: one piece)."""
    for b in blocks:
        if not piece_n:
            yield 1, b
            continue
        k = np.rint((b.t_s - t_origin) * rate_hz).astype(np.int64) // piece_n
        cuts = [0, *(np.flatnonzero(np.diff(k)) + 1), len(b)]
        for i, j in zip(cuts[:-1], cuts[1:]):
            yield int(k[i]) + 1, (b if j - i == len(b) else slice_block(b, i, j))


def _sleep_until(wall: float) -> None:
    d = wall - time.monotonic()
    if d > 0:
        time.sleep(d)


def build_sinks(args: argparse.Namespace) -> list[Sink]:
    """The sinks the command line asks for: Rerun (file and/or live) and the console."""
    from fogmon.sinks.console import ConsoleSink

    out: list[Sink] = []
    rrd, connect, serve = getattr(args, "rrd", None), getattr(args, "connect", None), getattr(args, "serve", False)
    if rrd or connect or serve:
        from fogmon.sinks.rerun_sink import RerunSink
        out.append(RerunSink(rrd_path=rrd, connect_url=connect, serve=serve,
                             bind=getattr(args, "bind", "127.0.0.1"), port=getattr(args, "port", 9876),
                             rotate=bool(getattr(args, "rotate_s", None))))
    out.append(ConsoleSink(quiet=getattr(args, "quiet", False)))
    return out
