"""A recording in memory (``Recording``) and what the replay log's two forms, CSV
(fogmon.formats.replay_log) and Parquet (fogmon.formats.parquet_log), share: the rate
columns' names (``rate_dph``, or ``rate_<axis>_dph`` per axis), the nominal sample rate
(Hz) and the uniform sample grid the samples sit on (s)."""
from __future__ import annotations

import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from fogmon.block import Block, axis_aux, is_axis_name, parse_axes
from fogmon.errors import FogmonError

#: a reader's name of what it read: "FILE topic T", "FILE message M", "FILE channel C", "FILE curve C"
_PART = re.compile(r"^(.*?)( (?:topic|message|channel|curve) .*)$", re.DOTALL)

#: the rate column of one axis of a multi-axis log
_AXIS_RATE = re.compile(r"rate_(.*)_dph")
#: without ``sample_rate_hz`` metadata the rate is 1 / the median interval of this many
#: first samples (so a reader need not hold the file to know it)
RATE_SAMPLES = 1 << 16
#: the highest sample rate a recording may state (Hz): beyond any gyro's output rate (FOGs stop near 10 kHz)
MAX_SAMPLE_RATE_HZ = 1e6
#: a file's time gaps may hold at most this many times the samples present in it: more is a
#: corrupt time stamp or rate, not an outage (a laptop suspended overnight between two hours
#: of recording is 4 times)
MAX_MISSING_RATIO = 100
#: a rate in `sample_rate_hz` metadata and the time stamps may differ by this fraction
RATE_TOLERANCE = 0.01


@dataclass
class Recording:
    """A whole recording in memory: ``t_s`` (s), ``rate_dph`` (deg/h), auxiliary
    channels by column name, ``meta`` from ``# key: value`` lines, and how many bad
    rows were skipped when reading tolerantly. Several axes: ``axes`` names them and
    ``rate_dph`` has one column per axis (aux as in fogmon.block); ``for_axis(name)``
    is the one-axis recording every one-axis analysis takes. ``line_of(i)``, where the
    reader knows it, is the file line of sample ``i`` (error messages name it)."""

    t_s: np.ndarray
    rate_dph: np.ndarray
    aux: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, str] = field(default_factory=dict)
    path: str | None = None
    skipped_rows: int = 0
    axes: tuple[str, ...] = ()
    line_of: Callable[[int], int] | None = field(default=None, repr=False, compare=False)

    @property
    def name(self) -> str:
        """The file's name, and the part of it read (a reader's "FILE topic /imu/data"):
        "imu_data.bag topic /imu/data" (a topic's slashes are not the file's folders)."""
        if not self.path:
            return "<memory>"
        m = _PART.match(self.path)
        return os.path.basename(m.group(1)) + m.group(2) if m else os.path.basename(self.path)

    @property
    def sample_rate_hz(self) -> float:
        """Nominal sample rate in Hz (``sample_rate_from``)."""
        return sample_rate_from(self.meta, self.t_s, self.name)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0]) + 1.0 / self.sample_rate_hz if len(self.t_s) else 0.0

    def __len__(self) -> int:
        return len(self.t_s)

    def grid_index(self) -> np.ndarray:
        """Index of every sample on the uniform grid t0 + k / fs (``grid_positions``),
        checked: a sample off the grid, or a grid more than MAX_MISSING_RATIO times
        longer than the samples present (``check_grid_length``), is a FogmonError naming
        the file's line where ``line_of`` knows it."""
        idx = grid_positions(self.t_s, float(self.t_s[0]) if len(self.t_s) else 0.0, self.sample_rate_hz, self.name,
                             line_of=self.line_of)
        if len(idx):
            check_grid_length(int(idx[-1]) + 1, len(idx), self.name, jump=self._largest_jump(idx))
        return idx

    def _largest_jump(self, idx: np.ndarray) -> Callable[[], tuple[int | None, float]]:
        """(file line or None, s) of the largest time step between samples on grid ``idx``."""
        def jump() -> tuple[int | None, float]:
            i = int(np.argmax(np.diff(idx))) + 1 if len(idx) > 1 else 0
            step = float(self.t_s[i] - self.t_s[i - 1]) if i else 0.0
            return (self.line_of(i) if self.line_of else None), step
        return jump

    def check_changes(self) -> None:
        """FogmonError when the rate never changes (a stuck or saturated output: no noise
        to fit, explain or evaluate)."""
        y = np.asarray(self.rate_dph, dtype=np.float64)
        y = y[np.isfinite(y)]
        if len(y) > 1 and float(np.min(y)) == float(np.max(y)):
            raise FogmonError(f"{self.name}: the rate is {y[0]:g} deg/h at every one of its {len(y)} samples: a "
                              f"stuck or saturated output has no noise to analyse")

    def axis_names(self) -> tuple[str, ...]:
        """The axes to analyse: ``axes``, or ("",) for a one-axis recording."""
        return self.axes or ("",)

    def for_axis(self, name: str) -> Recording:
        """The one-axis recording of axis ``name`` (its rate column, its aux as
        fogmon.block.axis_aux gives them, ``meta['axis']`` set); a one-axis recording
        is returned as it is."""
        if not self.axes:
            return self
        if name not in self.axes:
            raise FogmonError(f"{self.name}: no axis {name!r} (axes: {', '.join(self.axes)})")
        j = self.axes.index(name)
        return Recording(self.t_s, self.rate_dph[:, j], axis_aux(self.aux, self.axes, name),
                         {**self.meta, "axis": name}, self.path, self.skipped_rows, line_of=self.line_of)

    def to_block(self) -> Block:
        """The recording on its uniform sample grid: missing samples (time gaps) become
        invalid placeholders (rate and aux NaN), so gaps are never joined."""
        idx = self.grid_index()
        n = int(idx[-1]) + 1 if len(idx) else 0
        sample_rate_hz = self.sample_rate_hz
        t = self.t_s[0] + np.arange(n) / sample_rate_hz if n else np.zeros(0)
        if n == len(idx):
            return Block.make(self.t_s.copy(), self.rate_dph.copy(), aux={k: v.copy() for k, v in self.aux.items()},
                              axes=self.axes)
        t[idx] = self.t_s
        rate = np.full((n, *self.rate_dph.shape[1:]), np.nan)
        rate[idx] = self.rate_dph
        aux = {}
        for k, v in self.aux.items():
            a = np.full(n, np.nan)
            a[idx] = v
            aux[k] = a
        return Block.make(t, rate, aux=aux, axes=self.axes)


def sample_rate_from(meta: dict, t_s: np.ndarray, name: str) -> float:
    """Nominal sample rate (Hz): metadata ``sample_rate_hz`` when present, otherwise 1 /
    the median interval of the first RATE_SAMPLES samples ``t_s`` (s)."""
    if "sample_rate_hz" in meta:
        try:
            sample_rate_hz = float(meta["sample_rate_hz"])
        except ValueError:
            raise FogmonError(f"{name}: metadata sample_rate_hz is not a number: "
                              f"{meta['sample_rate_hz']!r}") from None
        if not (0 < sample_rate_hz <= MAX_SAMPLE_RATE_HZ):
            raise FogmonError(f"{name}: metadata sample_rate_hz must be > 0 and <= {MAX_SAMPLE_RATE_HZ:g} Hz, got "
                              f"{sample_rate_hz}")
        return sample_rate_hz
    if len(t_s) < 2:
        raise FogmonError(f"{name}: too few samples to know the sample rate")
    step = float(np.median(np.diff(t_s[:RATE_SAMPLES])))
    if not step >= 1.0 / MAX_SAMPLE_RATE_HZ:
        raise FogmonError(f"{name}: column time_s: median step {step!r} s: not time stamps of a sample rate "
                          f"up to {MAX_SAMPLE_RATE_HZ:g} Hz")
    return 1.0 / stamps_period(np.asarray(t_s[:RATE_SAMPLES], dtype=np.float64), step)


def stamps_period(t_s: np.ndarray, step: float) -> float:
    """The sample period (s) of time stamps ``t_s`` with median step ``step`` (s): the
    median step when its grid holds every stamp within a quarter period (an exact or a
    plainly jittered grid, as `grid_positions` requires); else, where the steps' median
    is not their typical value (jitter with a skewed distribution: a logger whose steps
    are 10-12 ms with a mean of 11.000 ms and a median of 11.139 ms), the least-squares
    slope of the stamps over their sample counts within the runs between gaps (steps of
    more than 1.5 median steps: a gap's length in periods is what the period is not yet
    known well enough to count), pooled over the runs."""
    t = t_s - t_s[0]
    k = t / step
    if len(t) < 3 or np.max(np.abs(k - np.rint(k))) <= 0.25:
        return step
    run = np.concatenate(([0], np.cumsum(np.diff(t) > 1.5 * step)))
    n = np.bincount(run).astype(np.float64)
    idx = np.arange(len(t), dtype=np.float64)
    c = idx - (np.bincount(run, idx) / n)[run]
    d = t - (np.bincount(run, t) / n)[run]
    den = float(np.dot(c, c))
    return float(np.dot(c, d)) / den if den > 0 else step


def check_grid_length(n_grid: int, n_present: int, name: str, field: str = "time_s",
                      jump: Callable[[], tuple[int | None, float]] | None = None) -> None:
    """A FogmonError when a grid of ``n_grid`` samples would hold more than
    MAX_MISSING_RATIO times the ``n_present`` samples a file has in gaps: a corrupt time
    stamp or rate, not an outage (checked before any array of that length is made).
    ``jump()``, called only then, gives the file line (or None) where the largest time
    step ends and that step in s, for the message."""
    if n_grid - n_present > MAX_MISSING_RATIO * max(n_present, 1):
        line, step = jump() if jump is not None else (None, 0.0)
        at = f"line {line}, column {field}" if line is not None else f"column {field}"
        largest = f"; {field} jumps by {step:.6g} s at this line" if line is not None and step > 0 else ""
        raise FogmonError(f"{name}: {at}: the time stamps span {n_grid:.4g} sample periods for "
                          f"{n_present} samples (more than {MAX_MISSING_RATIO} times as many missing as present"
                          f"{largest}): a corrupt time stamp or sample rate, not a gap")


def check_stated_rate(meta: dict, t_s: np.ndarray, name: str) -> None:
    """A FogmonError when the metadata ``sample_rate_hz`` and the rate of the first
    RATE_SAMPLES time stamps ``t_s`` (s; ``stamps_period``) differ by more than RATE_TOLERANCE (both
    numbers named): a rate that says 100 Hz over stamps 20 ms apart would count every
    other sample missing and halve every tau."""
    if "sample_rate_hz" not in meta or len(t_s) < 3:
        return
    stated = sample_rate_from(meta, t_s, name)
    measured = sample_rate_from({}, t_s, name)
    if abs(stated / measured - 1.0) > RATE_TOLERANCE:
        raise FogmonError(f"{name}: metadata sample_rate_hz says {stated:.6g} Hz but column time_s steps by "
                          f"{1 / measured:.6g} s = {measured:.6g} Hz: correct or remove the "
                          f"sample_rate_hz line, or give `force_rate` to keep {stated:.6g} Hz")


def grid_positions(
    t_s: np.ndarray, t0_s: float, sample_rate_hz: float, name: str, after: int = -1, line_of=None
) -> np.ndarray:
    """Index k of every sample on the uniform grid ``t0_s + k / fs`` (s, Hz). A sample more
    than a quarter period off the grid, or two samples in one period (also against grid
    index ``after`` of the sample before these), is a FogmonError naming the line when
    ``line_of(i)`` gives it."""
    k = (np.asarray(t_s) - t0_s) * sample_rate_hz
    idx = np.rint(k).astype(np.int64)
    off = np.abs(k - idx)

    def where(i: int) -> str:
        return f"line {line_of(i)}, column time_s: " if line_of else ""

    if len(off) and off.max() > 0.25:
        i = int(np.argmax(off))
        raise FogmonError(f"{name}: {where(i)}sample at time_s={float(t_s[i])!r} is {off[i]:.2f} sample "
                          f"periods off the {sample_rate_hz:g} Hz grid (is sample_rate_hz right?)")
    if len(idx) and (idx[0] <= after or np.any(np.diff(idx) < 1)):
        i = int(np.argmax(np.diff(idx, prepend=after) < 1))
        raise FogmonError(f"{name}: {where(i)}two samples within one {1 / sample_rate_hz:g} s period at "
                          f"time_s={float(t_s[i])!r}")
    return idx


def rate_axes(cols: list[str], where: str, shown: str) -> tuple[str, ...]:
    """The axes a header's columns ``cols`` name: () for one axis (``rate_dph``), else
    the ``<axis>`` of each ``rate_<axis>_dph`` column in header order. ``time_s`` and
    exactly one of the two forms are required and an axis name is letters and digits:
    FogmonError otherwise, starting with ``where`` (file and line) and naming the
    column; ``shown`` is the header as error messages show it."""
    if "time_s" not in cols:
        raise FogmonError(f"{where}: missing required column 'time_s' (header has: {shown})")
    per_axis = [(c, m.group(1)) for c in cols if (m := _AXIS_RATE.fullmatch(c))]
    if not per_axis and "rate_dph" not in cols:
        raise FogmonError(f"{where}: missing required column 'rate_dph' (one axis) or rate_<axis>_dph columns "
                          f"(several axes) (header has: {shown})")
    if per_axis and "rate_dph" in cols:
        raise FogmonError(f"{where}, column {per_axis[0][0]}: a header has rate_dph (one axis) or "
                          f"rate_<axis>_dph columns (several axes), not both")
    for c, a in per_axis:
        if not is_axis_name(a):
            raise FogmonError(f"{where}, column {c}: axis name {a!r} is not letters and digits")
    return tuple(a for _, a in per_axis)


def pick_axes(axes: tuple[str, ...], asked: str | None, name: str) -> tuple[str, ...] | None:
    """The axes ``asked`` (the ``axis`` option: a name or a comma list) keeps of a
    recording ``name`` with ``axes``: None when nothing is to be picked (not asked, or a
    one-axis recording, where ``axis`` is left to the decoders and readers that take it, as it
    always was). An axis the recording does not have is a FogmonError listing its axes."""
    if asked is None or not axes:
        return None
    want = parse_axes(asked)
    for a in want:
        if a not in axes:
            raise FogmonError(f"{name}: no axis {a!r} (axes: {', '.join(axes)})")
    return want


def rate_columns(axes: tuple[str, ...]) -> list[str]:
    """The rate column names: ``rate_dph`` for one axis, ``rate_<axis>_dph`` for several."""
    return [f"rate_{a}_dph" for a in axes] if axes else ["rate_dph"]


def recording_from_arrays(t_s, rate_dph, aux=None, meta=None, axes: tuple[str, ...] = ()) -> Recording:
    """A Recording from arrays (for notebooks and tests); with ``axes``, ``rate_dph``
    is (n, len(axes))."""
    return Recording(np.asarray(t_s, float), np.asarray(rate_dph, float),
                     {k: np.asarray(v, float) for k, v in (aux or {}).items()}, dict(meta or {}), axes=tuple(axes))
