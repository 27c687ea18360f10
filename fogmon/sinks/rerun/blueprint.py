"""The Rerun entities the monitor draws and its default layout (``blueprint``), built from
small view functions: the ``time`` timeline (recording time, s), the ADEV-curve and
heatmap entities, an axis's entity path (``axis_path``) and one view per quantity.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

from fogmon.sinks.base import COEFFICIENTS
from fogmon.sinks.rerun import plots as rp
from fogmon.sinks.rerun.style import AXIS_COLOUR_NAMES

#: The timeline of every entity: recording time in s.
TIMELINE = "time"
#: Entity of the ADEV curve (x = log10 tau/s, y = log10 ADEV/(deg/h), plots.loglog_transform).
CURVE = "adev_curve/log10"
#: Entity (view origin) of the DADEV heatmap (plots.log_heatmap).
HEATMAP = "dadev/heatmap"
#: Child of ``coef/<name>``: invisible points at the track's rounded y range (plots.nice_range).
Y_RANGE = "y_range"
#: Row shares of the layout (rates and aux | ADEV curve and heatmaps | coefficient tracks
#: and events): Rerun labels a plot's y ticks only at multiples of a power of ten >= 20
#: pixels apart, so the rates (e.g. +-450 deg/h: 9 steps of 100) need about 200 pixels;
#: the tracks' rounded ranges (plots.nice_range: <= 6 steps) need about 130.
ROW_SHARES = (1.0, 1.15, 1.75)


def axis_path(axis: str, path: str) -> str:
    """The entity of ``path`` for axis ``axis`` of a multi-axis stream (``axis/<axis>/<path>``);
    ``path`` itself for a one-axis stream (``axis`` "")."""
    return f"axis/{axis}/{path}" if axis else path


def heatmap_height(axes: tuple[str, ...]) -> float:
    """The DADEV heatmap's height in view units (plots.log_heatmap): taller for several
    axes, whose heatmaps sit side by side in narrower views."""
    return rp.HEAT_H if len(axes) < 2 else 1.75 * rp.HEAT_H


def blueprint(aux_names: Sequence[str] = (), curve_bounds=None, error_rate: bool = False,
              axes: tuple[str, ...] = (), accel_tab=None):
    """The default layout: rate (and error rate) over time beside one view per aux
    channel | current ADEV curve and DADEV heatmap | the five coefficient tracks (tall
    enough for their tick values, no legend: the title says what is drawn) and the
    event log, wide enough for its messages. Time-series views show the whole recording
    with linked time axes; the time cursor follows the newest data. ``curve_bounds``
    ((x0, x1), (y0, y1)) in decades frames the ADEV-curve view; ``error_rate``: a view of
    rate_dph - 3600 x rot_dps beside the raw rate. With ``axes`` (several): the rates,
    ADEV curves and each coefficient's tracks of all axes overlaid in one view each, one
    heatmap per axis side by side, the events of all. ``accel_tab`` (a container: the
    accelerometers' views, fogmon.sinks.rerun.accel): the layout above and it as two tabs."""
    import rerun.blueprint as rrb

    of = f" of axes {', '.join(axes)}" if axes else ""
    rates: list[rrb.Container | rrb.View] = [
        _series(*_over_axes("rate/rate_dph", axes), f"Rate (deg/h){of} over recording time (s)")]
    if error_rate:
        rates.append(_series(*_over_axes("rate/error_dph", axes),
                             f"Error rate_dph - 3600 x rot_dps (deg/h){of}, analysed"))
    aux_share = [min(3.0, 1.0 + 0.5 * len(aux_names))] if aux_names else []
    top = rrb.Horizontal(*rates, *_aux_views(aux_names), column_shares=[2.0] * len(rates) + aux_share)
    origin, contents = _over_axes("adev_curve", axes)
    curve = rrb.Spatial2DView(origin=origin, contents=contents,
                              name="Current window: ADEV (deg/h) vs tau (s), log-log",
                              visual_bounds=rp.loglog_bounds(*curve_bounds) if curve_bounds is not None else None)
    height = heatmap_height(axes)
    heat = [rrb.Tabs(
        rrb.Spatial2DView(origin=f"/{axis_path(a, HEATMAP)}", name=(
            f"{a}: DADEV heatmap" if a else "DADEV heatmap: ADEV (deg/h, colour) by tau (s, rows) and window end "
                                            "time (s, columns)"), visual_bounds=rp.heatmap_bounds(height)),
        _series(f"/{axis_path(a, 'dadev/log10_adev_dph')}", "$origin/**",
                f"{a}: DADEV lines" if a else "DADEV: log10 ADEV (deg/h) per tau (s) over time"),
    ) for a in (axes or ("",))]
    key = ", ".join(f"{a} {AXIS_COLOUR_NAMES[k % len(AXIS_COLOUR_NAMES)]}" for k, a in enumerate(axes))
    what = f": {key}; \u25bc upper limit" if axes else " with interval; \u25bc 95 % upper limit"
    coefs = [_series(*_over_axes(f"coef/{n}", axes), f"{n} ({u}){what}", legend=False)
             for n, u in COEFFICIENTS.items()]
    ev_origin, ev_contents = _over_axes("events", axes)
    side = rrb.Tabs(_event_log(ev_origin, ev_contents, f"Events{' (all axes)' if axes else ''}"),
                    _series("/counters", "$origin/**", "Source counters"),
                    rrb.TextDocumentView(origin="/session", name="Session"))
    shares = [1, 1.2] if not axes else [1.1, *[0.7] * len(heat)]
    tracks = rrb.Vertical(rrb.Horizontal(*coefs[:3]), rrb.Horizontal(*coefs[3:], side, column_shares=[1, 1, 1.15]))
    gyros = rrb.Vertical(top, rrb.Horizontal(curve, *heat, column_shares=shares), tracks,
                         row_shares=list(ROW_SHARES), name="Gyros (IEEE Std 952)" if accel_tab is not None else None)
    return rrb.Blueprint(gyros if accel_tab is None else rrb.Tabs(gyros, accel_tab, active_tab=0),
                         rrb.TimePanel(timeline=TIMELINE, play_state="following", state="collapsed"),
                         collapse_panels=True)


def _aux_views(aux_names: Sequence[str]) -> list:
    """One view per aux channel (each its own y axis and colour; its title names it, no
    legend), in a grid beside the rates."""
    import rerun.blueprint as rrb

    if not aux_names:
        return []
    views = [_series(f"/aux/{n}", "$origin/**", f"Aux {n}", legend=False) for n in aux_names]
    cols = len(views) if len(views) <= 3 else math.ceil(len(views) / 2)     # sink.AUX_ONE_ROW
    return [rrb.Grid(*views, grid_columns=cols)]


def _event_log(origin: str, contents: list[str] | str, name: str):
    """The event log: level and message (each message starts with its recording time in s
    and, of several axes, its axis), without the time and entity columns, which the
    viewer sizes too narrow to read."""
    import rerun.blueprint as rrb
    from rerun.blueprint.encodings import TextLogColumn, TimelineColumn

    return rrb.TextLogView(origin=origin, contents=contents, name=name, columns=rrb.TextLogColumns(
        timeline_columns=[TimelineColumn(TIMELINE, visible=False)],
        text_log_columns=[TextLogColumn("LogLevel"), TextLogColumn("Body")]))


def _over_axes(path: str, axes: tuple[str, ...]) -> tuple[str, list[str] | str]:
    """(origin, contents) of a view of ``path``: of one axis, its entity and children; of
    several, ``/`` with every axis's ``axis/<name>/path`` and its children."""
    if not axes:
        return f"/{path}", "$origin/**"
    shared = {"adev_curve": ["/adev_curve/**"], "events": ["/events"]}.get(path, [])  # grid, legend; stream events
    return "/", [*shared, *(f"/{axis_path(a, path)}/**" for a in axes)]


def _series(origin: str, contents: list[str] | str, name: str, legend: bool = True):
    """A time-series view of the whole recording (``contents``: entity queries, as Rerun's)."""
    import rerun as rr
    import rerun.blueprint as rrb

    shown = rr.TimeRange(start=rr.TimeRangeBoundary.infinite(), end=rr.TimeRangeBoundary.infinite())
    return rrb.TimeSeriesView(origin=origin, contents=contents, name=name, axis_x=rrb.TimeAxis(view_range=shown),
                              plot_legend=None if legend else rrb.PlotLegend(visible=False))
