"""The accelerometers' Rerun views (``AccelViews``): a tab of their own beside the gyros'
layout (fogmon.sinks.rerun.blueprint), built the same way. Entities, per accelerometer
``<name>`` (StreamInfo.accels; units in the names):

- ``accel/<name>/adev_curve/log10/adev_ug`` the current window's ADEV (micro-g) with its
  ``bounds`` and the fitted model (``model_ieee1293``, over the taus the fit used), as
  x = log10(tau / s), y = log10(ADEV / micro-g), all accelerometers overlaid on one decade
  grid (``accel/adev_curve/log10``, with its legend);
- ``accel/<name>/dadev/log10_adev_ug`` log10 of the ADEV (micro-g) at every tau, one row
  per window;
- ``accel/<name>/coef/<coefficient>`` each IEEE Std 1293 coefficient with its interval
  (value, lo, hi; windows where it is identifiable), ``.../upper_limit`` its 95 % upper
  limit elsewhere, ``.../y_range`` the track's range so far rounded out (plots.nice_range).
Each accelerometer has one colour in every view (its axis's, style.AXIS_COLOURS).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from fogmon.sinks.base import ACCEL_COEFFICIENTS
from fogmon.sinks.rerun import plots as rp
from fogmon.sinks.rerun.columns import _send_bounds, _send_curves, _send_models, _send_scalars
from fogmon.sinks.rerun.style import AXIS_COLOUR_NAMES, AXIS_COLOURS, _shades

#: The accelerometers' decade grid and legend (x = log10 tau/s, y = log10 ADEV/micro-g).
ACCEL_CURVE = "accel/adev_curve/log10"
#: Child of a coefficient track: the 95 % upper limit where it is not identifiable; its rounded range.
UPPER_LIMIT, Y_RANGE = "upper_limit", "y_range"

Queue = Callable[[str, Callable[[Any, str, np.ndarray, list], None], Any, list], None]


def accel_path(name: str, path: str) -> str:
    """The entity of ``path`` for accelerometer ``name``: ``accel/<name>/<path>``."""
    return f"accel/{name}/{path}"


class AccelViews:
    """What the Rerun sink draws of the accelerometers ``names``: the static series
    styles and grid (``log_static``), each window's rows (``frames``, through the sink's
    ``queue``) and the blueprint tab (``tab``)."""

    def __init__(self, names: tuple[str, ...], tau_s: np.ndarray) -> None:
        self.names, self.tau_s = names, np.asarray(tau_s, dtype=np.float64)
        self.colours = {a: AXIS_COLOURS[k % len(AXIS_COLOURS)] for k, a in enumerate(names)}
        self.decades: tuple[tuple[int, int], tuple[int, int]] = ((-2, 2), (0, 4))
        self._ranges: dict[str, tuple[float, float]] = {}

    def frame_from(self, aux: dict[str, np.ndarray]) -> None:
        """Frame the ADEV view from the first block's accelerometer samples (g): the ADEV
        at tau0 is about their scatter (as the gyros' view is framed)."""
        tau = self.tau_s
        x_dec = (math.floor(np.log10(tau[0])), math.ceil(np.log10(tau[-1]))) if len(tau) else (-2, 2)
        tops = []
        for a in self.names:
            v = np.asarray(aux.get(f"accel_{a}_g", np.zeros(0)), dtype=np.float64) * 1e6
            v = v[np.isfinite(v)]
            sd = float(np.std(v)) if len(v) > 1 else 0.0
            tops.append(math.ceil(math.log10(sd * 1.5)) if sd > 0 else 3)
        top = max(tops) if tops else 3
        self.decades = (x_dec, (top - max(3, math.ceil(0.3 * len(tau))), top + 1))

    def log_static(self, rec) -> None:
        """Series names and colours, the decade grid and the legend (static)."""
        import rerun as rr

        for a, c in self.colours.items():
            rec.log(accel_path(a, "adev_curve/log10"), rp.loglog_transform(), static=True)
            rec.log(accel_path(a, "dadev/log10_adev_ug"),
                    rr.SeriesLines(names=[f"{a}: tau={t:.4g} s" for t in self.tau_s]), static=True)
            for n, u in ACCEL_COEFFICIENTS.items():
                rec.log(accel_path(a, f"coef/{n}"), rr.SeriesLines(
                    names=[f"{a}: {n} ({u})", f"{a}: lo", f"{a}: hi"], colors=[c, c, c], widths=[2.0, 0.7, 0.7]),
                    static=True)
                rec.log(accel_path(a, f"coef/{n}/{UPPER_LIMIT}"), rr.SeriesPoints(
                    names=[f"{a}: upper limit (not identifiable)"], colors=[c], markers=["down"], marker_sizes=[3.0]),
                    static=True)
                rec.log(accel_path(a, f"coef/{n}/{Y_RANGE}"), rr.SeriesPoints(
                    names=["y axis range (rounded out), bottom", "y axis range (rounded out), top"],
                    colors=[(0, 0, 0, 0)] * 2, marker_sizes=[0.0, 0.0]), static=True)
        x_dec, y_dec = self.decades
        rec.log(ACCEL_CURVE, rp.loglog_transform(), static=True)
        rp.log_decade_grid(rec, ACCEL_CURVE, x_dec, y_dec, "s", "ug")

    def log_legend(self, rec, confidence: float) -> None:
        """The ADEV view's legend: each accelerometer's colour and the shades of its bounds and model."""
        items = [*((f"accelerometer {a}: measured ADEV", c) for a, c in self.colours.items()),
                 (f"darker: {100 * confidence:.1f} % bounds", rp.LABEL_COLOUR),
                 ("lighter: IEEE Std 1293 model", rp.LABEL_COLOUR)]
        rp.log_loglog_legend(rec, f"{ACCEL_CURVE}/legend", items, *self.decades)

    def frames(self, queue: Queue, dadev, fit, t_end_s: np.ndarray, name: str) -> None:
        """Accelerometer ``name``'s completed windows (``dadev`` in micro-g, ``fit`` an
        AccelFit) as rows for the sink's next flush."""
        with np.errstate(divide="ignore", invalid="ignore"):
            log_adev = np.log10(np.asarray(dadev.adev_dph, dtype=np.float64))
        queue(accel_path(name, "dadev/log10_adev_ug"), _send_scalars, t_end_s, list(log_adev))
        for n in ACCEL_COEFFICIENTS:
            c = getattr(fit, n)
            v, lo, hi = (np.asarray(getattr(c, k), dtype=np.float64) for k in ("value", "lo", "hi"))
            ident = np.asarray(c.identifiable, dtype=bool)
            ok = ident & np.isfinite(v) & np.isfinite(lo) & np.isfinite(hi)
            queue(accel_path(name, f"coef/{n}"), _send_scalars, t_end_s[ok], list(np.column_stack([v[ok], lo[ok],
                                                                                                    hi[ok]])))
            up = ~ident & np.isfinite(hi)
            queue(accel_path(name, f"coef/{n}/{UPPER_LIMIT}"), _send_scalars, t_end_s[up], list(hi[up]))
            drawn = np.where(ok[:, None], np.column_stack([v, lo, hi]), np.where(up, hi, np.nan)[:, None])
            self._queue_range(queue, name, n, t_end_s, drawn)
        tau = np.asarray(dadev.tau_s, dtype=np.float64)
        lx, dense = np.log10(tau), rp.model_taus(tau)
        misfit = np.asarray(fit.noise.misfit, dtype=bool).reshape(np.shape(dadev.adev_dph))
        model = np.asarray(fit.model_adev_ug(dense), dtype=np.float64).reshape(len(t_end_s), len(dense))
        bounds, light = _shades(self.colours[name])[:2]
        curve = accel_path(name, "adev_curve/log10")
        for i in range(len(t_end_s)):
            with np.errstate(divide="ignore", invalid="ignore"):
                ly, llo, lhi, lm = (np.log10(np.asarray(x, dtype=np.float64))
                                    for x in (dadev.adev_dph[i], dadev.lo_dph[i], dadev.hi_dph[i], model[i]))
            ok = np.isfinite(ly)
            if not ok.any():
                continue
            t = [float(t_end_s[i])]
            queue(f"{curve}/adev_ug", partial(_send_curves, colour=self.colours[name]), t,
                  [np.column_stack([lx[ok], ly[ok]])])
            b = ok & np.isfinite(llo) & np.isfinite(lhi)
            queue(f"{curve}/bounds", partial(_send_bounds, colour=bounds), t,
                  [(np.column_stack([lx[b], llo[b]]), np.column_stack([lx[b], lhi[b]]))])
            span = rp.model_span(tau, dadev.adev_dph[i], misfit[i])
            m_ok = (np.isfinite(lm) & (dense >= span[0]) & (dense <= span[1])) if span else np.zeros(0, bool)
            line = np.column_stack([np.log10(dense[m_ok]), lm[m_ok]]) if m_ok.sum() >= 2 else None
            queue(f"{curve}/model_ieee1293", partial(_send_models, colour=light), t, [line])

    def _queue_range(self, queue: Queue, name: str, coef: str, t_end_s: np.ndarray, drawn: np.ndarray) -> None:
        """The rounded-out range of everything coefficient ``coef``'s tracks (of every
        accelerometer: they share a view) drew so far, as ``y_range`` points."""
        w_lo, w_hi = np.fmin.reduce(drawn, axis=1), np.fmax.reduce(drawn, axis=1)
        prev = self._ranges.get(coef, (np.nan, np.nan))
        run_lo = np.fmin.accumulate(np.r_[prev[0], w_lo])[1:]
        run_hi = np.fmax.accumulate(np.r_[prev[1], w_hi])[1:]
        if len(run_lo):
            self._ranges[coef] = (float(run_lo[-1]), float(run_hi[-1]))
        ok = np.isfinite(run_lo) & np.isfinite(run_hi)
        queue(accel_path(name, f"coef/{coef}/{Y_RANGE}"), _send_scalars, t_end_s[ok],
              [np.array(rp.nice_range(a, b)) for a, b in zip(run_lo[ok], run_hi[ok], strict=True)])

    def tab(self):
        """The accelerometers' tab: their ADEV curves overlaid and their DADEV lines |
        the five coefficient tracks, each accelerometer in its colour."""
        import rerun.blueprint as rrb

        from fogmon.sinks.rerun.blueprint import ROW_SHARES, _series

        key = ", ".join(f"{a} {AXIS_COLOUR_NAMES[k % len(AXIS_COLOUR_NAMES)]}" for k, a in enumerate(self.names))
        contents = ["/accel/adev_curve/**", *(f"/{accel_path(a, 'adev_curve')}/**" for a in self.names)]
        curve = rrb.Spatial2DView(origin="/accel", contents=contents,
                                  name="Accelerometers, current window: ADEV (ug) vs tau (s), log-log",
                                  visual_bounds=rp.loglog_bounds(*self.decades))
        lines = rrb.Tabs(*(_series(f"/{accel_path(a, 'dadev/log10_adev_ug')}", "$origin/**",
                                   f"Accelerometer {a}: DADEV log10 ADEV (ug) per tau (s)") for a in self.names))
        coefs = [_series("/", [f"/{accel_path(a, f'coef/{n}')}/**" for a in self.names],
                         f"{n} ({u}): {key}; \u25bc upper limit", legend=False) for n, u in ACCEL_COEFFICIENTS.items()]
        return rrb.Vertical(rrb.Horizontal(curve, lines, column_shares=[1.1, 1.0]),
                            rrb.Horizontal(*coefs[1:4]), rrb.Horizontal(coefs[0], coefs[4]),
                            row_shares=[ROW_SHARES[1], ROW_SHARES[2] / 2 + 0.3, ROW_SHARES[2] / 2 + 0.3],
                            name="Accelerometers (IEEE Std 1293)")
