"""Timestamped samples from another tool's recording (a ROS bag, a ULog, an MDF4 or a LAS
file) on fogmon's uniform sample grid.

Such files carry one time stamp per sample (header stamps, logger clocks) with jitter and
no sequence counter. Each stamp step is rounded to a whole number of median steps, so a
step of k periods (k >= 2) means k - 1 samples are missing: they become invalid
placeholders with a ``gap`` event and are counted, as in a replay log
(fogmon.sources.files.replay_log). Rounding step by step (not against the first stamp) keeps a clock
that runs slightly off its nominal rate from turning into false gaps. The nominal rate is
then the grid periods over the span of the stamps. A step under half a period (a repeated
or backward stamp) is a one-line error naming the file, the sample and the time field.
Sample times are the grid, ``t0 + k / fs`` (s). An IMU file (a ROS Imu message, a PX4
gyro topic) gives its gyro axes as one multi-axis source (fogmon.block: one rate column
per axis), or one axis as a one-axis source (``imu_axes``).
"""
from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from fogmon.block import Block, Event, parse_axes
from fogmon.errors import FogmonError
from fogmon.formats.recording import Recording
from fogmon.sources import plausibility
from fogmon.sources.files.replay_log import FAST_BLOCK
from fogmon.sources.grid import MAX_GAP_EVENTS, ErrorEvents

#: deg/h per rad/s (ROS sensor_msgs/Imu and PX4 topics give rad/s)
DPH_PER_RPS = 3600.0 * 180.0 / math.pi
#: a stamp step below this many nominal periods is two samples in one period: an error
MIN_STEP_PERIODS = 0.5
#: the gyro axes of an IMU message or topic
IMU_AXES = ("x", "y", "z")


def grid_index(t_s: np.ndarray, where: str, time_field: str) -> tuple[np.ndarray, float]:
    """(grid index of every sample, nominal rate in Hz) from time stamps ``t_s`` (s, in
    file order): index = cumulative sum of the steps rounded to whole periods of the
    median step; rate = grid periods / time from the first stamp to the last (the median
    step of jittered stamps is off by up to the jitter; the whole span is not).
    ``where`` (file, topic) and ``time_field`` name the data in errors."""
    t = np.asarray(t_s, dtype=np.float64)
    if len(t) < 2:
        raise FogmonError(f"{where}: {len(t)} sample(s): too few to know the sample rate")
    if not np.all(np.isfinite(t)):
        i = int(np.argmax(~np.isfinite(t)))
        raise FogmonError(f"{where}: sample {i}, field {time_field}: time stamp is {t[i]!r}")
    step = np.diff(t)
    med = float(np.median(step))
    if not med > 0:
        raise FogmonError(f"{where}: field {time_field}: the median time step is {med!r} s (stamps not increasing)")
    periods = step / med
    if periods.min() < MIN_STEP_PERIODS:
        i = int(np.argmin(periods)) + 1
        raise FogmonError(f"{where}: sample {i}, field {time_field}: time stamp {t[i]!r} s is "
                          f"{step[i - 1]:+.3g} s after the previous one (nominal step {med:.6g} s): repeated or "
                          f"backward time stamps")
    idx = np.concatenate(([0], np.cumsum(np.maximum(np.rint(periods), 1)).astype(np.int64)))
    return idx, float(idx[-1]) / float(t[-1] - t[0])


class StampedSource:
    """Samples with their own time stamps -> Blocks on the uniform grid (see the module
    docstring). ``t_s`` (s), ``rate_dph`` (deg/h; with ``axes``, one column per axis),
    ``aux`` channels by name (arrays of the same length); ``where`` names the data in
    errors and events, ``name`` describes the source. Rates beyond +-``max_abs_dph``
    become invalid and are counted. Counters, as far as the blocks yielded reach:
    ``samples`` (present), ``samples_missing``, ``seq_gaps`` (time gaps),
    ``implausible_samples``, and where the file has any, ``null_samples`` (values
    present but not a number: invalid; these two count one per axis) plus the
    ``counters`` the reader gives (what it left out and why). ``to_recording()`` gives
    the same samples as a Recording for the batch commands (explain)."""

    #: the ROS topic the samples came from (set by fogmon.sources.files.rosbag; a Kalibr export names it)
    ros_topic: str | None = None

    def __init__(self, t_s, rate_dph, aux: dict | None, *, name: str, where: str, time_field: str,
                 meta: dict | None = None, max_abs_dph: float = plausibility.GENERIC_MAX_ABS_DPH,
                 counters: dict[str, int] | None = None, axes: tuple[str, ...] = ()) -> None:
        t = np.asarray(t_s, dtype=np.float64)
        self._idx, self.sample_rate_hz = grid_index(t, where, time_field)
        self.t_first_s = float(t[0])
        self._rate = np.asarray(rate_dph, dtype=np.float64)
        #: the axes of the blocks (() for one axis)
        self.axes = tuple(axes)
        if self._rate.shape != ((len(t), len(self.axes)) if self.axes else (len(t),)):
            raise ValueError(f"rate_dph has shape {self._rate.shape} for {len(t)} stamps and axes {self.axes}")
        self._aux = {k: np.asarray(v, dtype=np.float64) for k, v in (aux or {}).items()}
        self.aux_names = list(self._aux)
        self.name, self.where = name, where
        self.meta = {"sample_rate_hz": repr(self.sample_rate_hz), **(meta or {})}
        self.n_samples = int(self._idx[-1]) + 1
        self.t_last_s = self.t_first_s + (self.n_samples - 1) / self.sample_rate_hz
        self._max_abs_dph = max_abs_dph
        self.counters = {"samples": 0, "samples_missing": 0, "seq_gaps": 0, plausibility.COUNTER: 0,
                         **({"null_samples": 0} if np.isnan(self._rate).any() else {}), **(counters or {})}
        self._closed = False

    def blocks(self) -> Iterator[Block]:
        idx, c, n = self._idx, self.counters, FAST_BLOCK
        errors = ErrorEvents(c)
        step = np.diff(idx)
        gap_at = np.flatnonzero(step > 1)            # sample before each gap
        for start in range(0, self.n_samples, n):
            if self._closed:
                return
            stop = min(start + n, self.n_samples)
            a, b = np.searchsorted(idx, [start, stop])
            at = idx[a:b] - start
            t = self.t_first_s + np.arange(start, stop) / self.sample_rate_hz
            rate = np.full((stop - start, *self._rate.shape[1:]), np.nan)
            rate[at] = self._rate[a:b]
            aux = {}
            for k, v in self._aux.items():
                aux[k] = np.full(stop - start, np.nan)
                aux[k][at] = v[a:b]
            present = np.zeros((stop - start, *self._rate.shape[1:]), bool)   # every axis of a sample read
            present[at] = True
            null = present & np.isnan(rate)
            rate, n_bad = plausibility.gate(rate, self._max_abs_dph, present & ~null)
            if null.any():
                c["null_samples"] += int(np.count_nonzero(null))
            gaps = gap_at[(idx[gap_at] + 1 >= start) & (idx[gap_at] + 1 < stop)]
            events = [Event(float(t[idx[g] + 1 - start]), "gap",
                            f"{int(step[g]) - 1} sample(s) missing at t={t[idx[g] + 1 - start]:.6f} s (time gap "
                            f"in {self.where})") for g in gaps[:MAX_GAP_EVENTS]]
            if len(gaps) > MAX_GAP_EVENTS:
                events.append(Event(events[-1].t_s, "gap", f"{len(gaps) - MAX_GAP_EVENTS} more gaps in this block"))
            c["samples"] += int(b - a)
            c["samples_missing"] += stop - start - int(b - a)
            c["seq_gaps"] += len(gaps)
            c[plausibility.COUNTER] += n_bad
            bad = present & ~null & np.isnan(rate)                  # made invalid by the gate
            first = bad.any(axis=1) if self.axes else bad
            events += errors.poll(float(t[np.argmax(first)]))       # the first implausible sample's time
            yield Block.make(t, rate, present, aux, events, self.axes)

    def close(self) -> None:
        self._closed = True

    def to_recording(self) -> Recording:
        """The present, plausible samples on their grid times (gaps stay time gaps), with
        ``sample_rate_hz`` metadata: what ``read_replay_log`` gives for the same data
        (several axes: the samples plausible on every axis, as a replay log holds them)."""
        t = self.t_first_s + self._idx / self.sample_rate_hz
        rate, _ = plausibility.gate(self._rate, self._max_abs_dph)
        keep = np.isfinite(rate).all(axis=1) if self.axes else np.isfinite(rate)
        return Recording(t[keep], rate[keep], {k: v[keep] for k, v in self._aux.items()}, dict(self.meta),
                         path=self.where, axes=self.axes)


def imu_axes(asked: str | None, path: str) -> tuple[str, ...]:
    """The gyro axes ``asked`` (``axis``: a name or a comma list) of an IMU recording ``path``:
    all three, IMU_AXES, when not given; one (``z``: a one-axis source, as this reader
    always gave) or several in the order given (``x,y``). A name other than x, y, z is
    a FogmonError naming the file."""
    if asked is None:
        return IMU_AXES
    try:
        names = parse_axes(asked)
    except FogmonError as e:
        raise FogmonError(f"{path}: {e.message}") from None
    if any(a not in IMU_AXES for a in names):
        raise FogmonError(f"{path}: `axis` {asked}: the gyro axes of an IMU are x, y and z (one, or several "
                          f"separated by commas)")
    return names


def dph_per_unit(unit: str | None, where: str) -> float:
    """deg/h per unit of a rate channel whose unit a file states as ``unit`` (the one
    table, fogmon.units, with the spellings loggers use: ``deg/hr``, ``degs/sec``,
    ``rad/sec``...); ``where`` names the channel in errors."""
    from fogmon.units import DPH_PER_UNIT, canonical
    u = (unit or "").strip().lower().replace(" ", "").replace("degs", "deg").replace("sec", "s").replace("hr", "h")
    name = canonical(u) if u else None
    if name is None or DPH_PER_UNIT[name][0] != "rate":
        rates = ", ".join(k for k, (m, _) in DPH_PER_UNIT.items() if m == "rate")
        raise FogmonError(f"{where}: unit {unit!r} is not an angular rate fogmon knows ({rates}); give `rate_unit`")
    return DPH_PER_UNIT[name][1]
