"""What a run is asked to do and the window policy: ``PipelineConfig`` (the frozen options
fogmon.cli builds, or a caller by hand), the window and hop (``window_and_hop``: the
defaults of fogmon.window, checked against the sample rate and the samples the run will have),
the samples of a live run of ``duration_s`` (``live_samples``), and the check that per-axis
options cover the stream's axes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fogmon.errors import FogmonError
from fogmon.methods.live import LiveMethods
from fogmon.sim.model import SensorModel
from fogmon.window import default_window_s

#: What ``taus`` gives ``tau_grid``: a grid name, N per decade, or tau values in s.
TauSpec = str | int | np.ndarray
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
    fogmon.modelcheck), ``accels`` (the accelerometers analysed, by name: the aux channels
    ``accel_<name>_g``; None: every one the stream has, (): none)."""

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
    accels: tuple[str, ...] | None = None


def window_and_hop(config: PipelineConfig, sample_rate_hz: float, total_n: int | None,
                   name: str = "the recording") -> tuple[float, float]:
    """Window and hop (s) from ``window_s``/``hop_s`` or their defaults, checked
    against the sample rate and the samples the run will have (the record's ``total_n``,
    None when live, cut to ``duration_s``); FogmonError naming the option (and the
    recording, ``name``) otherwise."""
    duration_s = config.duration_s
    n_run = total_n
    if duration_s is not None:
        n_cut = round(duration_s * sample_rate_hz)
        if n_cut < 1:
            raise FogmonError(f"`duration_s` {duration_s:g} s is shorter than one sample at {sample_rate_hz:g} Hz")
        n_run = n_cut if total_n is None else min(total_n, n_cut)
    if n_run is not None and n_run < 8:
        what = f"{name} has" if n_run == total_n else "`duration_s` leaves"
        raise FogmonError(f"{what} {n_run} samples at {sample_rate_hz:g} Hz: an Allan deviation needs at least 8")
    window_s = config.window_s
    if window_s is None:
        window_s = default_window_s(sample_rate_hz, n_run)
        if total_n is None:  # live: the live window unless duration_s asks for a shorter run
            window_s = min(window_s, default_window_s(sample_rate_hz, None))
    if n_run is not None and window_s * sample_rate_hz > n_run:
        what = "the recording" if n_run == total_n else "the `duration_s` run"
        raise FogmonError(f"`window_s` {window_s:g} s is longer than {what} "
                          f"({n_run / sample_rate_hz:g} s = {n_run} samples)")
    if window_s * sample_rate_hz < 8:
        raise FogmonError(f"`window_s` {window_s:g} s holds fewer than 8 samples at {sample_rate_hz:g} Hz")
    hop_s = config.hop_s or window_s / 8
    if hop_s * sample_rate_hz < 1:
        raise FogmonError(f"`hop_s` {hop_s:g} s is shorter than one sample at {sample_rate_hz:g} Hz")
    if hop_s > window_s:
        raise FogmonError(f"`hop_s` {hop_s:g} s is longer than the window ({window_s:g} s): the samples "
                          f"between windows would never be analysed")
    return window_s, hop_s


def live_samples(duration_s: float, sample_rate_hz: float) -> int:
    """Samples of a live run of ``duration_s`` s from its first sample: those with
    t - t_first <= duration_s - half a sample period (the replay cut, too)."""
    return max(1, math.floor(duration_s * sample_rate_hz - 0.5 + 1e-9) + 1)


def _check_axis_options(cfg: PipelineConfig, axes: tuple[str, ...], source_name: str) -> None:
    """FogmonError naming the option when a one-axis ``thermal`` calibration, a per-axis
    calibration or a ``model`` of several axes does not cover the stream's ``axes`` (() = one axis)."""
    if axes and cfg.methods.thermal is not None:
        raise FogmonError(f"`thermal`: the calibration is for one axis and {source_name} has axes "
                          f"{', '.join(axes)}: select one with `axis` NAME")
    calibrated = sorted(a for a, m in cfg.axis_methods.items() if m.thermal is not None)
    if calibrated and set(axes) - set(calibrated):
        what = f"not for {', '.join(a for a in axes if a not in calibrated)}" if axes else f"{source_name} is one axis"
        raise FogmonError(f"`thermal`: the calibration has a thermal_drift effect for axes "
                          f"{', '.join(calibrated)} and {what}: select calibrated axes with `axis`")
    if axes and cfg.model is not None:
        missing = [a for a in axes if cfg.model.axes and a not in cfg.model.axes]
        if missing:
            raise FogmonError(f"`model`: the model has no [noise.{missing[0]}] table (its axes: "
                              f"{', '.join(cfg.model.axes)}; the stream's: {', '.join(axes)}); "
                              f"select one of its axes with `axis` NAME")
