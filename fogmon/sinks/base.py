"""The sink contract: what the pipeline hands its outputs (Rerun, archive, console) and
when. A sink subclasses ``Sink`` and overrides the events it needs; the pipeline knows
only this module, never a concrete sink (those are chosen in fogmon.cli)."""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from fogmon.block import Block, Event
from fogmon.davar.fit import NAMES, NoiseFit
from fogmon.davar.result import AdevResult, DadevResult
from fogmon.units import ACCEL_NAMES, coefficient_unit

if TYPE_CHECKING:
    from fogmon.davar.accel import AccelFit

#: IEEE-952 coefficients in the order they are shown -> their units.
COEFFICIENTS = {name: coefficient_unit(name) for name in NAMES}
#: An accelerometer's IEEE Std 1293 coefficients in the order they are shown -> their units.
ACCEL_COEFFICIENTS = {name: coefficient_unit(name) for name in ACCEL_NAMES}


@dataclass(frozen=True)
class StreamInfo:
    """What sinks learn before the first block: source, sample rate (Hz), window/hop (s),
    taus (s), auxiliary channel names, and the axes analysed (() for a one-axis stream;
    each then has its own engine, fits and ``frames`` calls)."""

    source_name: str
    sample_rate_hz: float
    window_s: float
    hop_s: float
    tau_s: np.ndarray
    aux_names: tuple[str, ...]
    #: what DAVAR analyses: "rate_dph", or "rate_dph - 3600 x rot_dps" (error vs reference rotation)
    analysed: str = "rate_dph"
    #: with a ``model`` (PipelineConfig): per axis ("" for a one-axis stream) the model's DADEV band at ``tau_s``
    #: (lo, median, hi in deg/h; lo/hi at the family-wise level of the live check), and
    #: that level (per window)
    model_bands: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict)
    model_alpha: float | None = None
    axes: tuple[str, ...] = ()
    #: the accelerometers analysed (each an ``accel_<name>_g`` aux channel): their names
    #: (``Sink.accel_frames``, ``Summary.accels``)
    accels: tuple[str, ...] = ()


@dataclass(kw_only=True)
class AccelSummary:
    """One accelerometer's part of the end-of-run account: its invalid or lost samples
    (NaN in its channel), the samples platform motion kept out, DADEV windows, the
    whole-run Allan deviation (micro-g: ``overall.adev_dph`` holds micro-g) and its
    IEEE Std 1293 fit."""

    n_invalid: int = 0
    motion_samples: int = 0
    n_windows: int = 0
    overall: AdevResult | None = None
    overall_fit: AccelFit | None = None
    overall_first_s: float = math.nan


@dataclass(kw_only=True)
class AxisSummary:
    """One axis's part of the end-of-run account: its invalid or lost samples, DADEV
    windows, the whole-run ADEV and fit, platform motion and model check."""

    n_invalid: int = 0
    n_windows: int = 0
    overall: AdevResult | None = None    # the whole run (its latest OVERALL_MAX_SAMPLES samples)
    overall_fit: NoiseFit | None = None  # NoiseFit of ``overall``
    overall_first_s: float = math.nan
    motion_spans: list = field(default_factory=list)   # MotionSpan: kept out of DAVAR and the fits
    motion_samples: int = 0       # valid samples the motion gate made invalid
    motion_in_tail: int = 0       # of them, samples in ``overall``'s span
    fit_with_motion: NoiseFit | None = None   # the whole-run fit with those samples analysed too
    model_check: dict | None = None   # with a model: fogmon.modelcheck.ModelWatch.summary()
    phases: dict | None = None    # with pumps/rot_dps aux channels: fogmon.phases.PhaseLog.summary()


@dataclass
class Summary(AxisSummary):
    """The end-of-run account: what was processed, the whole-run ADEV and fit, counters.
    A one-axis run's analysis is in the fields of AxisSummary and ``axes`` is empty; a
    run of several axes has one AxisSummary per axis in ``axes`` (in stream order), and
    of those fields only ``n_invalid`` (samples invalid on any axis) and ``n_windows``
    (windows per axis) are set. ``accels``: one AccelSummary per accelerometer analysed."""

    source_name: str
    sample_rate_hz: float
    window_s: float
    hop_s: float
    n_samples: int = 0
    t_first_s: float = math.nan
    t_last_s: float = math.nan
    wall_s: float = 0.0
    source_wall_s: float = 0.0    # wall time from opening the source to the end of the run, s
    interrupted: bool = False
    analysed: str = "rate_dph"    # what DAVAR analysed (see StreamInfo.analysed)
    failed: bool = False          # stopped by an error (reported by the caller, no summary)
    stopped: str = ""             # why a sink ended the run early (StopRun: an output could take no more)
    counters: dict[str, int] = field(default_factory=dict)
    event_counts: dict[str, int] = field(default_factory=dict)
    outputs: list[str] = field(default_factory=list)
    axes: dict[str, AxisSummary] = field(default_factory=dict)
    accels: dict[str, AccelSummary] = field(default_factory=dict)   # accelerometer name -> its account

    @property
    def duration_s(self) -> float:
        """Recording time covered, s."""
        return (self.t_last_s - self.t_first_s + 1.0 / self.sample_rate_hz) if self.n_samples else 0.0

    @property
    def speed_x(self) -> float:
        """Recording time / wall time."""
        return self.duration_s / self.wall_s if self.wall_s > 0 else math.inf


class StopRun(Exception):
    """Raised by a sink's ``block`` when its output can take no more (a full disk): the
    pipeline ends the run as a stop signal does (every sink finished, the summary
    printed) and notes the message in ``Summary.stopped``."""


class Sink:
    """Receives the pipeline's outputs; every method is optional (no-op here), called in
    this order: ``start`` once, then ``block``/``frames``/``events``/``rotate``/
    ``source_counters`` as the run goes, ``finish`` once (also after an error). Sinks
    finish in increasing ``finish_order`` (the console last, so it can name the files)."""

    finish_order = 0

    def start(self, info: StreamInfo) -> None:
        """The stream begins (before its first block)."""

    def block(self, block: Block) -> None:
        """The next samples (deg/h, s), on the source's grid."""

    def frames(self, dadev: DadevResult, fit: NoiseFit, t_end_s: np.ndarray, axis: str = "") -> None:
        """Completed windows of axis ``axis`` ("" for a one-axis stream): their DadevResult
        (T rows), its NoiseFit (arrays over T) and the recording time (s) of each window's
        last sample."""

    def accel_frames(self, dadev: DadevResult, fit: AccelFit, t_end_s: np.ndarray, accel: str) -> None:
        """Completed windows of accelerometer ``accel`` (StreamInfo.accels): their
        DadevResult (``adev_dph`` in micro-g), its AccelFit (arrays over windows) and the
        recording time (s) of each window's last sample."""

    def events(self, events: Sequence[Event]) -> None:
        """Events of the source (gaps, CRC errors, ...) and of the pipeline (jumps, motion)."""

    def rotate(self, piece: int, t_s: float) -> None:
        """Piece ``piece`` (from 1) of the outputs begins with the next block, at recording
        time ``t_s`` (PipelineConfig ``rotate_s``)."""

    def source_counters(self, t_s: float, counters: dict[str, int]) -> None:
        """The source's counters at recording time ``t_s`` (s), after each set of frames."""

    def finish(self, summary: Summary) -> None:
        """The run ended (``summary.failed``: by an error); close files, print."""
