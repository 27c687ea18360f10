"""Labelled plots drawn in Rerun 2-D (spatial) views, which have neither log axes,
tick labels on images nor colour bars: a log-log decade grid with labels in units, a
legend of coloured labels, and a heatmap image with labelled rows, columns and a colour
scale. Used by the monitor's Rerun sink and the explain .rrd.

Coordinates: a log-log plot entity carries ``loglog_transform`` (x = log10 tau, y = log10
value, y up); a heatmap entity is in image pixels (x right, y down), one pixel per column
and row, stretched by ``heatmap_transform``."""
from __future__ import annotations

from typing import Sequence

import numpy as np

#: View units per decade of a log-log plot (2-D views keep a 1:1 aspect; panels are wide).
LOGLOG_X_SCALE = 250.0
LOGLOG_Y_SCALE = 100.0
GRID_COLOUR = (90, 90, 90)
LABEL_COLOUR = (170, 170, 170)
#: Width (pixels) of a heatmap's colour scale and its gap to the heatmap.
SCALE_WIDTH, SCALE_GAP = 4, 6


def loglog_transform():
    """The Transform3D of a log-log plot entity: decades to view units, y up."""
    import rerun as rr

    return rr.Transform3D(scale=[LOGLOG_X_SCALE, -LOGLOG_Y_SCALE, 1.0])


def loglog_bounds(x_dec: tuple[int, int], y_dec: tuple[int, int]):
    """VisualBounds2D framing decades ``x_dec`` x ``y_dec`` with room for the labels."""
    import rerun.blueprint as rrb

    (x0, x1), (y0, y1) = x_dec, y_dec
    return rrb.VisualBounds2D(x_range=[LOGLOG_X_SCALE * (x0 - 0.5), LOGLOG_X_SCALE * (x1 + 0.2)],
                              y_range=[-LOGLOG_Y_SCALE * (y1 + 0.3), -LOGLOG_Y_SCALE * (y0 - 0.6)])


def log_decade_grid(rec, entity: str, x_dec: tuple[int, int], y_dec: tuple[int, int],
                    x_unit: str, y_unit: str) -> None:
    """Static grid lines at every decade of a log-log plot and their labels ("10 s",
    "0.1 deg/h") under ``entity`` (which carries ``loglog_transform``)."""
    import rerun as rr

    xs, ys = np.arange(x_dec[0], x_dec[1] + 1), np.arange(y_dec[0], y_dec[1] + 1)
    strips = [[[x, ys[0]], [x, ys[-1]]] for x in xs] + [[[xs[0], y], [xs[-1], y]] for y in ys]
    rec.log(f"{entity}/grid", rr.LineStrips2D(strips, colors=[GRID_COLOUR], radii=rr.Radius.ui_points(0.5)),
            static=True)
    labels = [f"{10.0**x:g} {x_unit}" for x in xs] + [f"{10.0**y:g} {y_unit}" for y in ys]
    pos = [[x, ys[0] - 0.2] for x in xs] + [[xs[0] - 0.25, y] for y in ys]
    rec.log(f"{entity}/grid_labels", rr.Points2D(pos, labels=labels, radii=rr.Radius.ui_points(0.5),
                                                 colors=[LABEL_COLOUR]), static=True)


def log_legend(rec, entity: str, items: Sequence[tuple[str, tuple[int, int, int]]],
               top_left: tuple[float, float], step: float) -> None:
    """A static legend: each label in its series' colour, one under the other from
    ``top_left`` (in the entity's coordinates) by ``step``."""
    import rerun as rr

    x, y = top_left
    pos = [[x, y + k * step] for k in range(len(items))]
    rec.log(entity, rr.Points2D(pos, labels=[t for t, _ in items], colors=[c for _, c in items],
                                radii=rr.Radius.ui_points(4.0)), static=True)


def colourise(values: np.ndarray, lo: float, hi: float, colormap: str) -> np.ndarray:
    """RGB (uint8, shape + (3,)) of ``values`` on a matplotlib colormap over lo..hi
    (clipped at the ends; NaN black)."""
    import matplotlib

    v = np.asarray(values, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        f = np.clip((v - lo) / (hi - lo), 0.0, 1.0)
    rgb = matplotlib.colormaps[colormap](np.nan_to_num(f))[..., :3]
    rgb[~np.isfinite(v)] = 0.0
    return np.round(255 * rgb).astype(np.uint8)


def heatmap_transform(n_cols: int, n_rows: int, aspect: float = 0.4):
    """The Transform3D stretching a heatmap of n_cols x n_rows pixels to ``aspect``
    (height / width)."""
    import rerun as rr

    return rr.Transform3D(scale=[1.0, max(1.0, aspect * n_cols / max(n_rows, 1)), 1.0])


def log_colour_scale(rec, entity: str, n_rows: int, n_cols: int, lo: float, hi: float, colormap: str,
                     ticks: Sequence[float], tick_text: Sequence[str], static: bool = False) -> None:
    """A vertical colour scale for a heatmap of ``n_rows`` x ``n_cols`` pixels
    whose colours span lo (bottom) .. hi (top): a gradient beside it on the right with
    labelled ``ticks`` (values in lo..hi)."""
    import rerun as rr

    steps = 64
    grad = np.linspace(hi, lo, steps)[:, None].repeat(SCALE_WIDTH, axis=1)
    x0 = n_cols + SCALE_GAP
    rec.log(f"{entity}/image", rr.Image(colourise(grad, lo, hi, colormap)), static=static)
    rec.log(entity, rr.Transform3D(translation=[x0, 0.0, 0.0], scale=[1.0, n_rows / steps, 1.0]), static=static)
    ys = [(hi - t) / (hi - lo) * n_rows for t in ticks]
    rec.log(f"{entity}_labels", rr.Points2D([[x0 + SCALE_WIDTH + 6, y] for y in ys], labels=list(tick_text),
                                            colors=[LABEL_COLOUR],
                                            radii=rr.Radius.ui_points(0.5)), static=static)


def log_row_labels(rec, entity: str, rows: Sequence[int], texts: Sequence[str], x: float = -6.0) -> None:
    """Static labels of heatmap rows (pixel row indices), left of the image."""
    import rerun as rr

    rec.log(entity, rr.Points2D([[x, r + 0.5] for r in rows], labels=list(texts), colors=[LABEL_COLOUR],
                                radii=rr.Radius.ui_points(0.5)), static=True)


def column_labels(rec, entity: str, cols: Sequence[float], texts: Sequence[str], n_rows: int,
                  static: bool = False) -> None:
    """Labels of heatmap columns (pixel column positions) under the image."""
    import rerun as rr

    rec.log(entity, rr.Points2D([[c, n_rows + 1.0] for c in cols], labels=list(texts), colors=[LABEL_COLOUR],
                                radii=rr.Radius.ui_points(0.5)), static=static)


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


def nice_ticks(lo: float, hi: float, n: int = 5) -> np.ndarray:
    """About ``n`` round values (1, 2, 5 x 10^k steps) between lo and hi."""
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return np.array([lo])
    raw = (hi - lo) / max(n - 1, 1)
    mag = 10.0 ** np.floor(np.log10(raw))
    step = mag * min((s for s in (1, 2, 5, 10) if s * mag >= raw), default=10)
    return np.arange(np.ceil(lo / step) * step, hi + 0.5 * step, step)
