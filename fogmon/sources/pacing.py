"""Replay pacing: as fast as possible, or at the recorded speed times a factor."""
from __future__ import annotations

import time


class Pacer:
    """``wait(t_s)`` sleeps until recording time ``t_s`` (s) is due: the first call sets
    the origin, later ones wait until ``(t_s - t_first) / speed`` s of wall time have
    passed. ``speed`` None (or 0) = no pacing."""

    def __init__(self, speed: float | None = None, clock=time.monotonic, sleep=time.sleep) -> None:
        self.speed = speed if speed else None
        self._clock, self._sleep = clock, sleep
        self._origin: tuple[float, float] | None = None

    def wait(self, t_s: float) -> None:
        if self.speed is None:
            return
        now = self._clock()
        if self._origin is None:
            self._origin = (t_s, now)
            return
        due = self._origin[1] + (t_s - self._origin[0]) / self.speed
        if due > now:
            self._sleep(due - now)
