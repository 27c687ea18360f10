"""Timestamped samples from another tool's recording (a ROS bag, a ULog, an MDF4 or a LAS
file, a CAN log) on fogmon's uniform sample grid.

The grid, the sample rate and what is irregular come from the stamps
(fogmon.sources.files.timing): missing samples become invalid placeholders with a ``gap``
event and are counted, as in a replay log (fogmon.sources.files.replay_log). A nominal
rate the caller knows (a DBC cycle time, ``sample_rate_hz``) is checked against the
stamps (``timing.check_nominal``); a forced one scales the stamps' clock to it. An
irregular series is refused unless ``resample_hz`` asks for block means on a coarser
grid (``timing.block_means``). Sample times are the grid, ``t0 + k / fs`` (s). An IMU
file (a ROS Imu message, a PX4 gyro topic) gives its gyro axes as one multi-axis source
(fogmon.block: one rate column per axis), or one axis as a one-axis source
(``imu_axes``).
"""
from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from fogmon.block import Block, Event, parse_axes
from fogmon.errors import FogmonError
from fogmon.formats.recording import Recording, check_grid_length
from fogmon.sources import plausibility
from fogmon.sources.base import OfflineSource
from fogmon.sources.files.replay_log import FAST_BLOCK
from fogmon.sources.files.timing import Timing, block_means, check_nominal, grid_index
from fogmon.sources.grid import MAX_GAP_EVENTS, ErrorEvents

#: deg/h per rad/s (ROS sensor_msgs/Imu and PX4 topics give rad/s)
DPH_PER_RPS = 3600.0 * 180.0 / math.pi
#: the gyro axes of an IMU message or topic
IMU_AXES = ("x", "y", "z")


class StampedSource(OfflineSource):
    """Samples with their own time stamps -> Blocks on the uniform grid (see the module
    docstring). ``t_s`` (s), ``rate_dph`` (deg/h; with ``axes``, one column per axis),
    ``aux`` channels by name (arrays of the same length); ``where`` names the data in
    errors and events, ``name`` describes the source. ``valid`` (per sample, or per
    sample and axis) marks what the device flagged invalid (counted ``invalid_samples``);
    ``seq`` (rolling counter, ``modulus``) refines the gaps. ``nominal_hz`` (what
    ``nominal_what`` says) is checked against the stamps unless ``force_rate``;
    ``resample_hz`` gives block means instead. Rates beyond +-``max_abs_dph`` become
    invalid and are counted. Counters, as far as the blocks yielded reach: ``samples``
    (present), ``samples_missing``, ``seq_gaps`` (time gaps), ``implausible_samples``,
    and where the file has any, ``null_samples`` (values present but not a number:
    invalid; these two count one per axis) plus the ``counters`` the reader gives (what
    it left out and why). ``timing``: what the stamps say (fogmon.sources.files.timing).
    ``to_recording()`` gives the same samples as a Recording for the batch commands."""

    #: the ROS topic the samples came from (set by fogmon.sources.files.rosbag; a Kalibr export names it)
    ros_topic: str | None = None

    def __init__(self, t_s, rate_dph, aux: dict | None, *, name: str, where: str, time_field: str,
                 meta: dict | None = None, max_abs_dph: float = plausibility.GENERIC_MAX_ABS_DPH,
                 counters: dict[str, int] | None = None, axes: tuple[str, ...] = (), valid=None, seq=None,
                 modulus: int | None = None, nominal_hz: float | None = None, nominal_what: str = "`sample_rate_hz`",
                 force_rate: bool = False, resample_hz: float | None = None) -> None:
        t = np.asarray(t_s, dtype=np.float64)
        rate = np.asarray(rate_dph, dtype=np.float64)
        #: the axes of the blocks (() for one axis)
        self.axes = tuple(axes)
        if rate.shape != ((len(t), len(self.axes)) if self.axes else (len(t),)):
            raise ValueError(f"rate_dph has shape {rate.shape} for {len(t)} stamps and axes {self.axes}")
        aux = {k: np.asarray(v, dtype=np.float64) for k, v in (aux or {}).items()}
        ok = np.ones(rate.shape, bool) if valid is None else np.asarray(valid, bool)
        if ok.ndim < rate.ndim:                     # one flag per sample: every axis
            ok = np.repeat(ok[:, None], rate.shape[-1], axis=1)
        flagged = ~ok
        extra = dict(counters or {})
        self.timing: Timing | None = None
        idx: np.ndarray
        if resample_hz is not None:
            idx, rate, aux, flagged, n_bad = _resampled(t, rate, aux, flagged, resample_hz, max_abs_dph, where,
                                                        time_field)
            extra.update({"samples_averaged": len(t), plausibility.COUNTER: n_bad})
            self.sample_rate_hz = float(resample_hz)
        else:
            idx, self.timing = grid_index(t, where, time_field, seq, modulus)
            if self.timing.irregular:
                raise FogmonError(irregular_message(self.timing, where))
            self.sample_rate_hz = check_nominal(self.timing, nominal_hz, nominal_what, where, force_rate)
        check_grid_length(int(idx[-1]) + 1, len(idx), where, time_field)
        self._idx: np.ndarray = idx
        self.t_first_s = float(t[0])
        self._rate, self._aux, self._flagged = rate, aux, flagged
        self.aux_names = list(self._aux)
        self.name, self.where = name, where
        self.meta = {"sample_rate_hz": repr(self.sample_rate_hz), **(meta or {})}
        self.n_samples = int(self._idx[-1]) + 1
        self.t_last_s = self.t_first_s + (self.n_samples - 1) / self.sample_rate_hz
        self._max_abs_dph = max_abs_dph
        self.counters = {"samples": 0, "samples_missing": 0, "seq_gaps": 0, plausibility.COUNTER: 0,
                         **({"invalid_samples": 0} if flagged.any() else {}),
                         **({"null_samples": 0} if np.isnan(self._rate[~flagged]).any() else {}), **extra}
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
            flagged = np.zeros(present.shape, bool)
            flagged[at] = self._flagged[a:b]
            null = present & ~flagged & np.isnan(rate)
            ok = present & ~flagged & ~null
            rate, n_bad = plausibility.gate(np.where(ok, rate, np.nan), self._max_abs_dph, ok)
            if null.any():
                c["null_samples"] += int(np.count_nonzero(null))
            if flagged.any():
                c["invalid_samples"] += int(np.count_nonzero(flagged.any(axis=1) if self.axes else flagged))
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
            bad = ok & np.isnan(rate)                               # made invalid by the gate
            first = bad.any(axis=1) if self.axes else bad
            events += errors.poll(float(t[np.argmax(first)]))       # the first implausible sample's time
            yield Block.make(t, rate, ok, aux, events, self.axes)

    def close(self) -> None:
        self._closed = True

    def to_recording(self) -> Recording:
        """The present, valid, plausible samples on their grid times (gaps stay time
        gaps), with ``sample_rate_hz`` metadata: what ``read_replay_log`` gives for the
        same data (several axes: the samples plausible on every axis, as a replay log
        holds them)."""
        t = self.t_first_s + self._idx / self.sample_rate_hz
        rate, _ = plausibility.gate(np.where(self._flagged, np.nan, self._rate), self._max_abs_dph)
        keep = np.isfinite(rate).all(axis=1) if self.axes else np.isfinite(rate)
        return Recording(t[keep], rate[keep], {k: v[keep] for k, v in self._aux.items()}, dict(self.meta),
                         path=self.where, axes=self.axes)


def irregular_message(timing: Timing, where: str) -> str:
    """Why an irregular series is refused and the resampling that fixes it."""
    hint = timing.resample_hint_hz()
    odd = (timing.gaps + timing.bursts) / (timing.n - 1)
    why = ("no uniform grid holds the samples at their stamps: samples would sit at the wrong times and every "
           "tau there would be off" if timing.drifting else
           f"{odd:.0%} of the steps are gaps or under half a period: the Allan deviation would keep few whole terms")
    return (f"{where}: irregular time stamps: {timing.describe()}; {why}; "
            f"give `resample_hz` (block means on a coarser grid, e.g. {_nice(hint)}; docs/readers.md)")


def _nice(hz: float) -> str:
    """A rate for a message: 3 significant digits, rounded down."""
    if not hz > 0:
        return "1"
    e = 10 ** (math.floor(math.log10(hz)) - 2)
    return f"{math.floor(hz / e) * e:.6g}"


def _resampled(t: np.ndarray, rate: np.ndarray, aux: dict, flagged: np.ndarray, resample_hz: float,
               max_abs_dph: float, where: str, time_field: str):
    """(block index, block-mean rate, block-mean aux, no flags, implausible samples) of
    ``timing.block_means`` over the samples that are valid and plausible."""
    if len(t) < 2:
        raise FogmonError(f"{where}: {len(t)} sample(s): too few to resample")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        grid_index(t, where, time_field)    # raises with the sample and the field
    gated, n_bad = plausibility.gate(np.where(flagged, np.nan, rate), max_abs_dph, ~flagged & np.isfinite(rate))
    j, means, _ = block_means(t, gated, resample_hz, where)
    aux_means = {k: block_means(t, v, resample_hz, where)[1] for k, v in aux.items()}
    return j, means, aux_means, np.zeros(means.shape, bool), n_bad


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


def nearest_samples(t_from: np.ndarray, values: np.ndarray, t_at: np.ndarray) -> np.ndarray:
    """``values`` (stamped ``t_from``, increasing) at the times ``t_at`` (increasing, same
    clock): the sample nearest in time within half the median step of ``t_at``, else NaN
    (an aux channel logged with its own stamps, e.g. an accelerometer beside a gyro)."""
    t_from, t_at = np.asarray(t_from, dtype=np.float64), np.asarray(t_at, dtype=np.float64)
    out = np.full(len(t_at), np.nan)
    if len(t_from) == 0 or len(t_at) == 0:
        return out
    j = np.clip(np.searchsorted(t_from, t_at), 1, len(t_from) - 1) if len(t_from) > 1 else np.zeros(len(t_at), int)
    if len(t_from) > 1:
        j = np.where(np.abs(t_from[j - 1] - t_at) <= np.abs(t_from[j] - t_at), j - 1, j)
    half = 0.5 * float(np.median(np.diff(t_at))) if len(t_at) > 1 else math.inf
    ok = np.abs(t_from[j] - t_at) <= half
    out[ok] = np.asarray(values, dtype=np.float64)[j[ok]]
    return out

