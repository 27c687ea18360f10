"""Operating phases of a run from its aux channels, and the noise coefficients per phase:
the drilling engineer's session summary (docs/monitor.md).

A window's state comes from the aux channels that say what the tool is doing: ``pumps``
(mud pumps, 1 on / 0 off) and ``rot_dps`` (drill-string, turntable or orbital rotation,
deg/s). States are named from the channels a recording has (``state_words``): with
``pumps`` (a drilling run) "pumps on, rotating", "pumps off, not rotating", ...; with
``rot_dps`` alone (a rate table, a gyro in orbit) the rotation is only said against its
threshold ("|rot_dps| <= 1 deg/s"), since "not rotating" would be false of an orbiting
gyro turning at 0.06 deg/s. A window is in a state when at least STATE_FRACTION of its
valid aux samples are; otherwise it straddles a change (``transition``) and belongs to
no phase. Consecutive windows in one state make a phase; each phase keeps the range
(min..max over its windows) of every IEEE-952 coefficient the window fits identified.
Runs without those channels have one state, ``steady``.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from fogmon.davar.fit import NAMES

#: A window is in a state when this fraction of its aux samples are.
STATE_FRACTION = 0.9
#: |rot_dps| above this (deg/s) is rotating (1 rpm = 6 deg/s; a stationary gyro reads Earth
#: rate, 0.004 deg/s, and a rate table's settling stays well below it).
ROTATING_DPS = 1.0
#: ``pumps`` above this is on (the channel is 1 on / 0 off).
PUMPS_ON = 0.5
#: The aux channels a state is read from.
STATE_CHANNELS = ("pumps", "rot_dps")
TRANSITION = "transition"
STEADY = "steady"


#: Each state channel: the words for its two values (off, on) in a drilling run (with
#: ``pumps``), and the test for "on".
_DRILLING_WORDS = {"pumps": ("pumps off", "pumps on"), "rot_dps": ("not rotating", "rotating")}


def state_channels(names) -> tuple[str, ...]:
    """The state channels (STATE_CHANNELS, in that order) among the channel ``names``."""
    return tuple(c for c in STATE_CHANNELS if c in names)


def state_words(channels: tuple[str, ...]) -> dict[str, tuple[str, str]]:
    """Per state channel of a recording with exactly these ``channels`` (state_channels):
    the words for its two values (off, on). Drilling words only with ``pumps``; a rotation
    alone is said against its threshold."""
    if "pumps" in channels:
        return {c: _DRILLING_WORDS[c] for c in channels}
    return {c: (f"|{c}| <= {ROTATING_DPS:g} deg/s", f"|{c}| > {ROTATING_DPS:g} deg/s") for c in channels}


def _on(name: str, x: np.ndarray) -> np.ndarray:
    return x > PUMPS_ON if name == "pumps" else np.abs(x) > ROTATING_DPS


def window_state(aux: Mapping[str, np.ndarray]) -> str:
    """The state of a window from its aux samples: STEADY without state channels, the
    state of at least STATE_FRACTION of its known samples (a sample is unknown where a
    state channel is NaN), else TRANSITION. Samples are counted by an integer code (one
    bit per channel), not by name, so a long window costs one bincount."""
    names = state_channels(aux)
    if not names:
        return STEADY
    code = np.zeros(len(aux[names[0]]), dtype=np.int64)
    known = np.ones(len(code), dtype=bool)
    for bit, name in enumerate(names):
        x = np.asarray(aux[name], dtype=float)
        code |= _on(name, x).astype(np.int64) << bit
        known &= ~np.isnan(x)
    counts = np.bincount(code[known], minlength=1 << len(names))
    if not counts.sum():
        return TRANSITION
    k = int(np.argmax(counts))
    if counts[k] < STATE_FRACTION * counts.sum():
        return TRANSITION
    words = state_words(names)
    return ", ".join(words[name][(k >> bit) & 1] for bit, name in enumerate(names))


@dataclass
class Phase:
    """Consecutive windows in one state: the recording time (s) of the first and last
    window's end, the number of windows, and per coefficient (fit.NAMES, IEEE-952 units)
    the (min, max) of its identified values (absent when never identified)."""

    state: str
    t_first_end_s: float
    t_last_end_s: float
    windows: int = 0
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)

    def add(self, t_end_s: float, values: Mapping[str, float]) -> None:
        self.t_last_end_s = t_end_s
        self.windows += 1
        for name, v in values.items():
            lo, hi = self.ranges.get(name, (v, v))
            self.ranges[name] = (min(lo, v), max(hi, v))


class PhaseLog:
    """The phases of a run, window by window (:meth:`frame`), and their summary."""

    def __init__(self) -> None:
        self.phases: list[Phase] = []
        self.channels: tuple[str, ...] = ()   # the state channels the windows had
        self.transitions = 0
        self._broken = False  # a transition since the last phase's window: the next window starts a phase

    def frame(self, t_end_s: float, aux: Mapping[str, np.ndarray], values: Mapping[str, float],
              identifiable: Mapping[str, bool]) -> Phase | None:
        """One window ending at ``t_end_s`` (s) with its aux samples and fitted coefficients
        (name -> value in IEEE-952 units, and whether identified); returns the phase it
        starts, if it starts one."""
        self.channels = state_channels(aux)
        state = window_state(aux)
        if state == TRANSITION:
            self.transitions += 1
            self._broken = True
            return None
        new = None
        if not self.phases or self.phases[-1].state != state or self._broken:
            new = Phase(state, t_end_s, t_end_s)
            self.phases.append(new)
        kept = {n: float(values[n]) for n in NAMES if identifiable.get(n) and np.isfinite(values.get(n, np.nan))}
        self.phases[-1].add(t_end_s, kept)
        self._broken = False
        return new

    def summary(self) -> dict:
        """Per state: the phases (time span of their window ends, windows), their number,
        the windows, and the coefficient ranges over all its phases; windows straddling a
        change of state (``transition_windows``) are in none; ``channels``: the state
        channels the states were read from."""
        by_state: dict[str, dict] = {}
        for p in self.phases:
            s = by_state.setdefault(p.state, {"phases": [], "windows": 0, "ranges": {}})
            s["phases"].append({"t_first_end_s": p.t_first_end_s, "t_last_end_s": p.t_last_end_s,
                                "windows": p.windows, "ranges": dict(p.ranges)})
            s["windows"] += p.windows
            for name, (lo, hi) in p.ranges.items():
                a, b = s["ranges"].get(name, (lo, hi))
                s["ranges"][name] = (min(a, lo), max(b, hi))
        return {"states": by_state, "transition_windows": self.transitions, "channels": list(self.channels)}
