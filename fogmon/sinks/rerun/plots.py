"""Labelled plots drawn in Rerun 2-D (spatial) views, which have neither log axes,
tick labels on images nor colour bars: a log-log decade grid with labels in units, a
legend of coloured labels beside it, model bands as bars, marked tau spans, and a
heatmap image with labelled rows, columns, a colour scale and a key for cells without
a value. Used by the monitor's Rerun sink and the explain .rrd. Also the rounded y range
that keeps a time-series view's tick values readable (``nice_range``), and where a fitted
model's curve is drawn (``model_span``, ``model_taus``).

Coordinates: a log-log plot entity carries ``loglog_transform`` (x = log10 tau, y = log10
value, y up; a child of the view's origin, as a view ignores its origin's own
transform); a heatmap fills HEAT_W x ``height`` view units (x right, y down) whatever its
number of rows and columns, so its view can be framed in the blueprint
(``heatmap_bounds``). Text has a fixed size in pixels whatever the view's zoom: the
viewer hangs a point's label just below the point, centred on it, so labels meant to sit
beside a row or grid line are anchored higher, short tick marks show the exact place, and
a legend's lines are stacked by line breaks (pixels), not by view units."""
from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

import numpy as np

#: View units per decade of a log-log plot (2-D views keep a 1:1 aspect; panels are wide).
LOGLOG_X_SCALE = 250.0
LOGLOG_Y_SCALE = 100.0
#: Decades of tau kept free right of a log-log grid for its legend (``log_loglog_legend``).
LEGEND_DECADES = 2.6
GRID_COLOUR = (90, 90, 90)
LABEL_COLOUR = (170, 170, 170)
#: Heatmap cells without a value (NaN: no estimate at that tau in that window), and the
#: key above the colour scale that says so.
NO_DATA_COLOUR = (128, 128, 128)
NO_DATA_KEY = "\u25a0 no estimate"
#: A heatmap's default size in view units, its colour scale's gap and width, the room for
#: labels left, right, above (the no-estimate key, a note) and below (time labels), and how
#: far a label is anchored above its tick (the viewer hangs a label below its point; this
#: centres it at the panel sizes of the default layouts).
HEAT_W, HEAT_H = 100.0, 40.0
SCALE_GAP, SCALE_WIDTH = 5.0, 3.0
HEAT_LEFT, HEAT_RIGHT, HEAT_TOP, HEAT_BOTTOM = 18.0, 34.0, 8.5, 8.5
LABEL_DROP = 1.5


def loglog_transform():
    """The Transform3D of a log-log plot entity: decades to view units, y up."""
    import rerun as rr

    return rr.Transform3D(scale=[LOGLOG_X_SCALE, -LOGLOG_Y_SCALE, 1.0])


def loglog_bounds(x_dec: tuple[int, int], y_dec: tuple[int, int]):
    """VisualBounds2D framing decades ``x_dec`` x ``y_dec`` with room for the labels and,
    right of the grid, LEGEND_DECADES for the legend (``log_loglog_legend``)."""
    import rerun.blueprint as rrb

    (x0, x1), (y0, y1) = x_dec, y_dec
    return rrb.VisualBounds2D(x_range=[LOGLOG_X_SCALE * (x0 - 1.2), LOGLOG_X_SCALE * (x1 + 0.2 + LEGEND_DECADES)],
                              y_range=[-LOGLOG_Y_SCALE * (y1 + 0.3), -LOGLOG_Y_SCALE * (y0 - 0.9)])


def log_decade_grid(rec, entity: str, x_dec: tuple[int, int], y_dec: tuple[int, int],
                    x_unit: str, y_unit: str) -> None:
    """Static grid lines at every decade of a log-log plot and their labels ("10 s";
    "100 deg/h" at the top, "10", "1", "0.1" below, short enough to stay clear of the
    x labels in a narrow view) under ``entity`` (which carries ``loglog_transform``)."""
    import rerun as rr

    xs, ys = np.arange(x_dec[0], x_dec[1] + 1), np.arange(y_dec[0], y_dec[1] + 1)
    strips = [[[x, ys[0]], [x, ys[-1]]] for x in xs] + [[[xs[0], y], [xs[-1], y]] for y in ys]
    rec.log(f"{entity}/grid", rr.LineStrips2D(strips, colors=[GRID_COLOUR], radii=rr.Radius.ui_points(0.5)),
            static=True)
    labels = [f"{10.0**x:g} {x_unit}" for x in xs] + [f"{10.0**y:g}" + (f" {y_unit}" if y == ys[-1] else "")
                                                       for y in ys]
    pos = [[x, ys[0] - 0.2] for x in xs] + [[xs[0] - 0.55, y + 0.15] for y in ys]
    rec.log(f"{entity}/grid_labels", rr.Points2D(pos, labels=labels, radii=rr.Radius.ui_points(0.5),
                                                 colors=[LABEL_COLOUR]), static=True)


def log_loglog_legend(rec, entity: str, items: Sequence[tuple[str, tuple[int, int, int]]],
                      x_dec: tuple[int, int], y_dec: tuple[int, int]) -> None:
    """A static legend right of the grid of decades ``x_dec`` x ``y_dec`` (in the room
    ``loglog_bounds`` keeps free): each label in its series' colour, one under the other
    from the grid's top (``log_stacked_labels``)."""
    log_stacked_labels(rec, entity, items, (x_dec[1] + 0.2 + LEGEND_DECADES / 2, y_dec[1] + 0.1))


def log_stacked_labels(rec, entity: str, items: Sequence[tuple[str, tuple[int, int, int]]],
                       at: tuple[float, float]) -> None:
    """Static coloured labels one text line under the other, the first hanging from ``at``
    (in the entity's coordinates), each centred on it: label k is anchored at ``at`` too
    and starts with k line breaks, so the lines are spaced in pixels whatever the view's
    zoom. The lowest (longest) label is logged first, so each label's background is
    drawn before the text above it."""
    import rerun as rr

    labels = ["\n" * k + t for k, (t, _) in enumerate(items)][::-1]
    colours = [c for _, c in items][::-1]
    rec.log(entity, rr.Points2D([list(at)] * len(items), labels=labels, colors=colours,
                                radii=rr.Radius.ui_points(0.0)), static=True)


def stacked_label_texts(labels: Sequence[str]) -> list[str]:
    """The texts of ``log_stacked_labels``'s labels (as logged: lowest first, with their
    line breaks) from the top down."""
    return [t.lstrip("\n") for t in reversed(labels)]


def log_band_bars(rec, entity: str, lx: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  colour: tuple[int, int, int], dx: float = 0.0) -> None:
    """A static band of a log-log plot (log10 tau ``lx``, log10 bounds ``lo``..``hi``) drawn
    as a translucent vertical bar at each tau, shifted by ``dx`` decades (two bands side
    by side), so it shows even where its edge lines run along other curves."""
    import rerun as rr

    ok = np.isfinite(lx) & np.isfinite(lo) & np.isfinite(hi)
    bars = [[[x + dx, a], [x + dx, b]] for x, a, b in zip(lx[ok], lo[ok], hi[ok], strict=True)]
    if bars:
        rec.log(entity, rr.LineStrips2D(bars, colors=[(*colour, 150)], radii=rr.Radius.ui_points(3.0),
                                        draw_order=5.0), static=True)      # under the curves


def log_tau_spans(rec, entity: str, spans: Sequence[tuple[float, float, str]], y_dec: tuple[int, int],
                  colour: tuple[int, int, int]) -> None:
    """Static marks on a log-log plot (``loglog_transform``) of tau ranges (lo, hi in s)
    with their labels: a box over the plot's height (decades ``y_dec``) from half an
    octave below ``lo`` to half an octave above ``hi``, its label hanging from its top
    (the labels of boxes at one place one under the other)."""
    import rerun as rr

    if not spans:
        return
    half = 0.5 * np.log10(2.0)
    y0, y1 = y_dec
    boxes: list[list[list[float]]] = []
    pos: list[list[float]] = []
    labels: list[str] = []
    for lo, hi, text in spans:
        x0, x1 = np.log10(lo) - half, np.log10(hi) + half
        boxes.append([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
        at = [0.5 * (x0 + x1), y1 - 0.05]
        labels.append("\n" * pos.count(at) + text)
        pos.append(at)
    rec.log(f"{entity}/boxes", rr.LineStrips2D(boxes, colors=[colour], radii=rr.Radius.ui_points(1.5)), static=True)
    rec.log(f"{entity}/labels", rr.Points2D(pos[::-1], labels=labels[::-1], colors=[colour],
                                            radii=rr.Radius.ui_points(0.0)), static=True)


def colourise(values: np.ndarray, lo: float, hi: float, colormap: str) -> np.ndarray:
    """RGB (uint8, shape + (3,)) of ``values`` on a matplotlib colormap over lo..hi
    (clipped at the ends), the colour matplotlib gives, rounded to 8 bits; NaN (no
    value) NO_DATA_COLOUR."""
    table = colour_table(colormap)
    v = np.asarray(values, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        f = np.nan_to_num(np.clip((v - lo) / (hi - lo), 0.0, 1.0))
    rgb = table[np.minimum((f * len(table)).astype(np.intp), len(table) - 1)]   # matplotlib's binning
    rgb[~np.isfinite(v)] = NO_DATA_COLOUR
    return rgb


#: matplotlib's "viridis" (the monitor's heatmap) as colour_table gives it: without
#: importing matplotlib (0.2 CPU s of a replay's start-up).
_VIRIDIS = np.frombuffer(bytes.fromhex(
    "44015444025645045745055946075a46085c460a5d460b5e470d60470e61471063471164471365481467481668481769"
    "48186a481a6c481b6d481c6e481d6f481f70482071482173482374482475482576482677482878482979472a7a472c7a"
    "472d7b472e7c472f7d46307e46327e46337f463480453581453781453882443983443a83443b84433d84433e85423f85"
    "4240864241864142874144874045884046883f47883f48893e49893e4a893e4c8a3d4d8a3d4e8a3c4f8a3c508b3b518b"
    "3b528b3a538b3a548c39558c39568c38588c38598c375a8c375b8d365c8d365d8d355e8d355f8d34608d34618d33628d"
    "33638d32648e32658e31668e31678e31688e30698e306a8e2f6b8e2f6c8e2e6d8e2e6e8e2e6f8e2d708e2d718e2c718e"
    "2c728e2c738e2b748e2b758e2a768e2a778e2a788e29798e297a8e297b8e287c8e287d8e277e8e277f8e27808e26818e"
    "26828e26828e25838e25848e25858e24868e24878e23888e23898e238a8d228b8d228c8d228d8d218e8d218f8d21908d"
    "21918c20928c20928c20938c1f948c1f958b1f968b1f978b1f988b1f998a1f9a8a1e9b8a1e9c891e9d891f9e891f9f88"
    "1fa0881fa1881fa1871fa28720a38620a48621a58521a68522a78522a88423a98324aa8325ab8225ac8226ad8127ad81"
    "28ae8029af7f2ab07f2cb17e2db27d2eb37c2fb47c31b57b32b67a34b67935b77937b87838b9773aba763bbb753dbc74"
    "3fbc7340bd7242be7144bf7046c06f48c16e4ac16d4cc26c4ec36b50c46a52c56954c56856c66758c7655ac8645cc863"
    "5ec96260ca6063cb5f65cb5e67cc5c69cd5b6ccd5a6ece5870cf5773d05675d05477d1537ad1517cd2507fd34e81d34d"
    "84d44b86d54989d5488bd6468ed64590d74393d74195d84098d83e9bd93c9dd93ba0da39a2da37a5db36a8db34aadc32"
    "addc30b0dd2fb2dd2db5de2bb8de29bade28bddf26c0df25c2df23c5e021c8e020cae11fcde11dd0e11cd2e21bd5e21a"
    "d8e219dae319dde318dfe318e2e418e5e419e7e419eae51aece51befe51cf1e51df4e61ef6e620f8e621fbe723fde725"
), dtype=np.uint8).reshape(256, 3)


@lru_cache(maxsize=8)
def colour_table(colormap: str) -> np.ndarray:
    """The colours (uint8 RGB, one row per level, read-only) of a matplotlib colormap."""
    if colormap == "viridis":
        return _VIRIDIS
    import matplotlib

    cmap = matplotlib.colormaps[colormap]
    table = np.round(255 * cmap(np.arange(cmap.N))[:, :3]).astype(np.uint8)   # integers: one row each
    table.flags.writeable = False
    return table


def heatmap_bounds(height: float = HEAT_H):
    """VisualBounds2D of a view showing ``log_heatmap`` of ``height`` (its labels, colour
    scale, key and note included)."""
    import rerun.blueprint as rrb

    return rrb.VisualBounds2D(x_range=[-HEAT_LEFT, HEAT_W + SCALE_GAP + SCALE_WIDTH + HEAT_RIGHT],
                              y_range=[-HEAT_TOP, height + HEAT_BOTTOM])


def log_heatmap(rec, entity: str, values: np.ndarray, lo: float, hi: float, colormap: str,
                row_ticks: tuple[Sequence[int] | np.ndarray, Sequence[str]],
                col_ticks: tuple[Sequence[int] | np.ndarray, Sequence[str]],
                scale_ticks: tuple[Sequence[float] | np.ndarray, Sequence[str]] | None, static: bool = False,
                height: float = HEAT_H) -> None:
    """``values`` (rows x columns, row 0 on top) as an image of HEAT_W x ``height`` view
    units under ``entity`` (a view's origin), coloured on ``colormap`` over lo..hi (NaN
    cells NO_DATA_COLOUR); labelled rows and columns (indices, texts) with tick marks, and
    the colour scale of ``log_heatmap_scale`` at ``scale_ticks`` (None: left as drawn
    before, for a sink that redraws the map every window on a fixed scale)."""
    import rerun as rr

    n_rows, n_cols = np.shape(values)
    sx, sy = HEAT_W / n_cols, height / n_rows
    rec.log(f"{entity}/map", rr.Transform3D(scale=[sx, sy, 1.0]), static=static)
    rec.log(f"{entity}/map/image", rr.Image(colourise(values, lo, hi, colormap)), static=static)
    ry = [(r + 0.5) * sy for r in row_ticks[0]]
    cx = [(c + 0.5) * sx for c in col_ticks[0]]
    ticks = [[[-1.5, y], [0.0, y]] for y in ry] + [[[x, height], [x, height + 1.5]] for x in cx]
    rec.log(f"{entity}/ticks", rr.LineStrips2D(ticks, colors=[LABEL_COLOUR], radii=rr.Radius.ui_points(0.5)),
            static=static)
    pos = [[-HEAT_LEFT / 2, y - LABEL_DROP] for y in ry] + [[x, height + 1.5] for x in cx]
    rec.log(f"{entity}/labels", rr.Points2D(pos, labels=[*row_ticks[1], *col_ticks[1]],
                                            colors=[LABEL_COLOUR], radii=rr.Radius.ui_points(0.0)), static=static)
    if scale_ticks is not None:
        log_heatmap_scale(rec, entity, lo, hi, colormap, scale_ticks, static, height)


def log_heatmap_scale(rec, entity: str, lo: float, hi: float, colormap: str,
                      scale_ticks: tuple[Sequence[float] | np.ndarray, Sequence[str]], static: bool = False,
                      height: float = HEAT_H) -> None:
    """The colour scale right of ``log_heatmap``'s map under ``entity``: ``colormap``
    over lo..hi (top: hi), labelled at ``scale_ticks`` (values in lo..hi, texts), and
    above it the key of the cells without a value (NO_DATA_KEY in NO_DATA_COLOUR)."""
    import rerun as rr

    steps = 64
    grad = np.linspace(hi, lo, steps)[:, None].repeat(2, axis=1)
    x0 = HEAT_W + SCALE_GAP
    rec.log(f"{entity}/scale", rr.Transform3D(translation=[x0, 0.0, 0.0], scale=[SCALE_WIDTH / 2, height / steps, 1.0]),
            static=static)
    rec.log(f"{entity}/scale/image", rr.Image(colourise(grad, lo, hi, colormap)), static=static)
    x1 = x0 + SCALE_WIDTH
    sy = [(hi - v) / (hi - lo) * height for v in scale_ticks[0]]
    rec.log(f"{entity}/scale_ticks", rr.LineStrips2D([[[x1, y], [x1 + 1.5, y]] for y in sy], colors=[LABEL_COLOUR],
                                                     radii=rr.Radius.ui_points(0.5)), static=static)
    rec.log(f"{entity}/scale_labels", rr.Points2D([[x1 + HEAT_RIGHT / 2, y - LABEL_DROP] for y in sy],
                                                  labels=list(scale_ticks[1]), colors=[LABEL_COLOUR],
                                                  radii=rr.Radius.ui_points(0.0)), static=static)
    rec.log(f"{entity}/no_data_key", rr.Points2D([[x0 + SCALE_WIDTH / 2, -HEAT_TOP]],
                                                 labels=[NO_DATA_KEY], colors=[NO_DATA_COLOUR],
                                                 radii=rr.Radius.ui_points(0.0)), static=static)


def log_heatmap_note(rec, entity: str, text: str, colour: tuple[int, int, int]) -> None:
    """A static note above ``log_heatmap``'s map under ``entity``, centred over it."""
    import rerun as rr

    rec.log(f"{entity}/note", rr.Points2D([[HEAT_W / 2, -HEAT_TOP]], labels=[text], colors=[colour],
                                          radii=rr.Radius.ui_points(0.0)), static=True)


def decade_rows(values: np.ndarray) -> list[int]:
    """Indices of ``values`` (log-spaced, e.g. taus) to label: one per decade, the one
    nearest a power of ten, else every row when there are few."""
    lv = np.log10(np.asarray(values, dtype=np.float64))
    if len(lv) <= 6:
        return list(range(len(lv)))
    out = []
    for d in range(int(np.floor(lv.min())), int(np.ceil(lv.max())) + 1):
        i = int(np.argmin(np.abs(lv - d)))
        if abs(lv[i] - d) < 0.35 and i not in out:
            out.append(i)
    return out


def nice_ticks(lo: float, hi: float, n: int = 7) -> np.ndarray:
    """About ``n`` round values (steps of 1, 2 or 5 x 10^k) within lo..hi."""
    raw = (hi - lo) / max(n - 1, 1)
    mag = 10.0 ** np.floor(np.log10(raw))
    step = mag * min(s for s in (1, 2, 5, 10) if s * mag >= raw)
    t = np.arange(np.ceil(lo / step), np.floor(hi / step) + 1) * step
    return t[(t >= lo) & (t <= hi)]


def nice_range(lo: float, hi: float, max_steps: int = 6) -> tuple[float, float]:
    """``lo``..``hi`` rounded out to multiples of a power of ten spanning at most
    ``max_steps`` of them (1 <= steps): the y range of a time-series view whose tick
    values show. Rerun's plots label only multiples of powers of ten, each step only
    where its ticks are >= 20 pixels apart, and fit the y axis to the data: 0.0035..0.09
    in a 150-pixel panel shows just "0"; rounded out to 0..0.1 it shows "0" and "0.1"
    with a grid line every 0.01."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"nice_range: lo and hi must be finite, got {lo}, {hi}")
    lo, hi = min(lo, hi), max(lo, hi)
    span = hi - lo if hi > lo else max(abs(hi), 1e-300)
    step = 10.0 ** math.floor(math.log10(span))
    while True:
        a, b = math.floor(lo / step) * step, math.ceil(hi / step) * step
        if b == a:
            b = a + step
        if round((b - a) / step) <= max_steps:
            return a, b
        step *= 10.0


#: Model points per decade of tau drawn over the fitted range.
MODEL_POINTS_PER_DECADE = 20


def model_span(tau_s: np.ndarray, adev_dph: np.ndarray, misfit: np.ndarray) -> tuple[float, float] | None:
    """(first, last) tau (s) the fit described: measured and not flagged as misfit; the
    model is drawn only there (beyond, it extrapolates terms the fit never saw). None
    when no tau was fitted."""
    used = np.isfinite(np.asarray(adev_dph, dtype=np.float64)) & ~np.asarray(misfit, dtype=bool)
    if not used.any():
        return None
    k = np.flatnonzero(used)
    return float(tau_s[k[0]]), float(tau_s[k[-1]])


def model_taus(tau_s: np.ndarray) -> np.ndarray:
    """The taus (s) the model curve is drawn at: every tau of the grid and, between
    neighbours, log-spaced points (MODEL_POINTS_PER_DECADE per decade); read-only,
    computed once per tau grid (every window of a run has the same)."""
    return _model_taus(tuple(np.asarray(tau_s, dtype=np.float64).tolist()))


@lru_cache(maxsize=8)
def _model_taus(tau: tuple[float, ...]) -> np.ndarray:
    parts = [np.geomspace(a, b, max(1, math.ceil(MODEL_POINTS_PER_DECADE * math.log10(b / a))) + 1)[:-1]
             for a, b in zip(tau[:-1], tau[1:], strict=True)]
    out = np.concatenate([*parts, np.asarray(tau[-1:])])
    out.flags.writeable = False
    return out
