"""What the Rerun sink sends in columns (``send_columns``): the raw traces' display
decimator (means of consecutive samples), an entity's rows waiting for the next flush,
and one sender per kind of row (scalars, texts, ADEV curves, bounds, model curves).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fogmon.sinks.rerun.blueprint import TIMELINE


class _Decimator:
    """Means of ``step`` consecutive samples (invalid/NaN ignored), carrying the remainder."""

    def __init__(self, step: int):
        self.step = step
        self._t: list[np.ndarray] = []
        self._v: dict[str, list[np.ndarray]] = {}

    def push(self, t: np.ndarray, values: dict[str, np.ndarray]) -> None:
        self._t.append(t)
        for k, v in values.items():
            self._v.setdefault(k, []).append(v)

    def pending(self) -> int:
        return sum(len(t) for t in self._t)

    def take(self, final: bool = False) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(times, {name: values}) of completed bins; time = first sample of each bin."""
        if not self._t:
            return np.zeros(0), {}
        t = np.concatenate(self._t)
        vals = {k: np.concatenate(v) for k, v in self._v.items()}
        s = self.step
        n_full = (len(t) // s) * s if not final else len(t)
        keep = slice(n_full, None)
        self._t = [t[keep]] if n_full < len(t) else []
        self._v = {k: [v[keep]] for k, v in vals.items()} if n_full < len(t) else {}
        if s == 1:
            return t[:n_full], {k: v[:n_full] for k, v in vals.items()}
        nb = -(-n_full // s)
        pad = nb * s - n_full
        tb = t[:n_full:s]
        out = {}
        for k, v in vals.items():
            x = np.concatenate([v[:n_full], np.full(pad, np.nan)]).reshape(nb, s)
            cnt = np.count_nonzero(np.isfinite(x), axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                out[k] = np.where(cnt > 0, np.nansum(x, axis=1) / np.maximum(cnt, 1), np.nan)
        return tb, out


@dataclass
class _Rows:
    """One entity's rows waiting for the next flush: their times (s), their values, and
    ``send(rec, entity, t_s, values)``, which sends them in columns."""

    send: Callable[[Any, str, np.ndarray, list], None]
    t_s: list[float] = field(default_factory=list)
    values: list = field(default_factory=list)


def _time_index(t_s: np.ndarray) -> list:
    """The ``time`` index of rows at ``t_s`` (s)."""
    import rerun as rr

    return [rr.TimeColumn(TIMELINE, duration=t_s)]


def _ui_radii(points: float, n: int) -> np.ndarray:
    """``n`` radii of ``points`` UI points each (Rerun's negative-radius convention)."""
    import rerun as rr

    return np.full(n, rr.Radius.ui_points(points), dtype=np.float32)


def _send_scalars(rec, entity: str, t_s: np.ndarray, values: list) -> None:
    """Scalars rows (each row a value or equal-length values)."""
    import rerun as rr

    rec.send_columns(entity, indexes=_time_index(t_s), columns=rr.Scalars.columns(scalars=np.array(values)))


def _send_texts(rec, entity: str, t_s: np.ndarray, values: list) -> None:
    """TextLog rows, each (text, level)."""
    import rerun as rr

    rec.send_columns(entity, indexes=_time_index(t_s), columns=rr.TextLog.columns(
        text=[v[0] for v in values], level=[v[1] for v in values]))


def _send_curves(rec, entity: str, t_s: np.ndarray, values: list, colour: tuple[int, int, int]) -> None:
    """Measured ADEV curves, each row a (k, 2) array of points: a line through them and the points."""
    import rerun as rr

    n = len(values)
    rec.send_columns(entity, indexes=_time_index(t_s), columns=[
        *rr.LineStrips2D.columns(strips=values, colors=[colour] * n, radii=_ui_radii(1.5, n)),
        *rr.Points2D.columns(positions=np.concatenate(values)).partition([len(v) for v in values]),
        *rr.Points2D.columns(colors=[colour] * n, radii=_ui_radii(3.0, n))])


def _send_bounds(rec, entity: str, t_s: np.ndarray, values: list, colour: tuple[int, int, int]) -> None:
    """Confidence bounds, each row (lower line, upper line)."""
    import rerun as rr

    n = len(values)
    rec.send_columns(entity, indexes=_time_index(t_s), columns=[
        *rr.LineStrips2D.columns(strips=[line for v in values for line in v]).partition([2] * n),
        *rr.LineStrips2D.columns(colors=[colour] * n, radii=_ui_radii(1.0, n))])


def _send_models(rec, entity: str, t_s: np.ndarray, values: list, colour: tuple[int, int, int]) -> None:
    """Model curves, each row a line, or None: cleared (no model drawn in that window)."""
    import rerun as rr

    drawn = [i for i, v in enumerate(values) if v is not None]
    cleared = [i for i, v in enumerate(values) if v is None]
    if drawn:
        n = len(drawn)
        rec.send_columns(entity, indexes=_time_index(t_s[drawn]), columns=rr.LineStrips2D.columns(
            strips=[values[i] for i in drawn], colors=[colour] * n, radii=_ui_radii(1.0, n),
            draw_order=[40.0] * n))   # above the measured curve it follows
    if cleared:
        rec.send_columns(entity, indexes=_time_index(t_s[cleared]),
                         columns=rr.Clear.columns(is_recursive=[False] * len(cleared)))
