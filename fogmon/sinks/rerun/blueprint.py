"""The Rerun entities the monitor draws and its default layout (``blueprint``), built from
small view functions: the ``time`` timeline (recording time, s), the ADEV-curve and
heatmap entities, an axis's entity path (``axis_path``) and one view per quantity.
"""
from __future__ import annotations

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


def axis_path(axis: str, path: str) -> str:
    """The entity of ``path`` for axis ``axis`` of a multi-axis stream (``axis/<axis>/<path>``);
    ``path`` itself for a one-axis stream (``axis`` "")."""
    return f"axis/{axis}/{path}" if axis else path


def blueprint(aux_names: Sequence[str] = (), curve_bounds=None, error_rate: bool = False,
              axes: tuple[str, ...] = ()):
    """The default layout: rate and aux over time | current ADEV curve and DADEV heatmap |
    a grid of the five coefficient tracks (tall enough for tick labels) and the event log.
    Time-series views show the whole recording with linked time axes; the time cursor
    follows the newest data. ``curve_bounds`` ((x0, x1), (y0, y1)) in decades frames the
    ADEV-curve view; ``error_rate``: a view of rate_dph - 3600 x rot_dps beside the raw rate.
    With ``axes`` (several): the rates, ADEV curves and each coefficient's tracks of all
    axes overlaid in one view each, one heatmap per axis side by side, the events of all."""
    import rerun.blueprint as rrb

    of = f" of axes {', '.join(axes)}" if axes else ""
    top: list[rrb.Container | rrb.View] = [
        _series(*_over_axes("rate/rate_dph", axes), f"Rate (deg/h){of} over recording time (s)")]
    if error_rate:
        top.append(_series(*_over_axes("rate/error_dph", axes),
                           f"Error rate_dph - 3600 x rot_dps (deg/h){of}, analysed"))
    if aux_names:
        top.append(_series("/aux", "$origin/**", "Aux channels (units in names)"))
    origin, contents = _over_axes("adev_curve", axes)
    curve = rrb.Spatial2DView(origin=origin, contents=contents,
                              name=f"Current window: ADEV (deg/h) vs tau (s){of}, log-log",
                              visual_bounds=rp.loglog_bounds(*curve_bounds) if curve_bounds is not None else None)
    heat = [rrb.Tabs(
        rrb.Spatial2DView(origin=f"/{axis_path(a, HEATMAP)}",
                          name=f"{_axis_title(a)}DADEV heatmap: ADEV (deg/h, colour) by tau (s, rows) and window "
                               "end time (s, columns)", visual_bounds=rp.heatmap_bounds()),
        _series(f"/{axis_path(a, 'dadev/log10_adev_dph')}", "$origin/**",
                f"{_axis_title(a)}DADEV: log10 ADEV (deg/h) per tau (s) over time"),
    ) for a in (axes or ("",))]
    key = ", ".join(f"{a} {AXIS_COLOUR_NAMES[k % len(AXIS_COLOUR_NAMES)]}" for k, a in enumerate(axes))
    coefs = [_series(*_over_axes(f"coef/{n}", axes), f"{n} ({u}): value, interval or upper limit"
                     + (f" ({key})" if axes else ""), legend=not axes)    # 3 series per axis: a key, no legend
             for n, u in COEFFICIENTS.items()]
    side = rrb.Tabs(rrb.TextLogView(origin=(ev := _over_axes("events", axes))[0], contents=ev[1],
                                    name=f"Events{' (all axes)' if axes else ''}"),
                    _series("/counters", "$origin/**", "Source counters"),
                    rrb.TextDocumentView(origin="/session", name="Session"))
    shares = [1, 1.2] if not axes else [1.6, *[0.8] * len(heat)]
    return rrb.Blueprint(rrb.Vertical(rrb.Horizontal(*top), rrb.Horizontal(curve, *heat, column_shares=shares),
                                      rrb.Grid(*coefs, side, grid_columns=3),
                                      row_shares=[1.4, 1.6, 2.4]),
                         rrb.TimePanel(timeline=TIMELINE, play_state="following", state="collapsed"),
                         collapse_panels=True)


def _over_axes(path: str, axes: tuple[str, ...]) -> tuple[str, list[str] | str]:
    """(origin, contents) of a view of ``path``: of one axis, its entity and children; of
    several, ``/`` with every axis's ``axis/<name>/path`` and its children."""
    if not axes:
        return f"/{path}", "$origin/**"
    shared = {"adev_curve": ["/adev_curve/**"], "events": ["/events"]}.get(path, [])  # grid, legend; stream events
    return "/", [*shared, *(f"/{axis_path(a, path)}/**" for a in axes)]


def _axis_title(axis: str) -> str:
    """The prefix of a one-axis view's title ("Axis x: "; none for a one-axis stream)."""
    return f"Axis {axis}: " if axis else ""


def _series(origin: str, contents: list[str] | str, name: str, legend: bool = True):
    """A time-series view of the whole recording (``contents``: entity queries, as Rerun's)."""
    import rerun as rr
    import rerun.blueprint as rrb

    shown = rr.TimeRange(start=rr.TimeRangeBoundary.infinite(), end=rr.TimeRangeBoundary.infinite())
    return rrb.TimeSeriesView(origin=origin, contents=contents, name=name, axis_x=rrb.TimeAxis(view_range=shown),
                              plot_legend=None if legend else rrb.PlotLegend(visible=False))
