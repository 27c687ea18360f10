"""How the monitor's Rerun views are coloured: the ADEV curve's measured, bounds, model
and model-band colours, the coefficients' colours, the heatmap's colormap, one colour
per aux channel (``aux_colour``), and for a stream of several axes one colour per axis
with its shades (``_styles``).
"""
from __future__ import annotations

from dataclasses import dataclass

from fogmon.sinks.base import COEFFICIENTS

#: Colours of the ADEV-curve view (its legend uses the same).
MEASURED_COLOUR, BOUNDS_COLOUR, MODEL_COLOUR = (255, 255, 255), (120, 160, 255), (255, 170, 0)
#: the --model band around the live curve
BAND_COLOUR = (200, 90, 200)
HEATMAP_COLORMAP = "viridis"
#: Colours of the axes of a multi-axis stream, in the order of StreamInfo.axes (x red, y green,
#: z blue, as 3-D viewers draw them), repeated beyond six axes.
AXIS_COLOURS = ((235, 90, 80), (90, 200, 100), (90, 150, 255), (230, 180, 40), (200, 110, 220), (70, 200, 200))
#: What the views' titles call those colours.
AXIS_COLOUR_NAMES = ("red", "green", "blue", "yellow", "purple", "cyan")
#: Colours of the aux channels, in the order of StreamInfo.aux_names (each in its own
#: view), repeated beyond six channels; none is an axis colour.
AUX_COLOURS = ((255, 190, 90), (180, 140, 255), (120, 220, 200), (240, 120, 170), (200, 200, 120), (150, 200, 255))
_COEF_COLORS = {"Q_arcsec": (230, 159, 0), "N_dpsh": (86, 180, 233), "B_dph": (0, 158, 115),
                "K_dphsh": (213, 94, 0), "R_dphh": (204, 121, 167)}


@dataclass(frozen=True)
class _Style:
    """How one axis is drawn: the prefix of its series names ("x: "; "" for a one-axis
    stream) and its colours (RGB; ``rate`` None: Rerun's default)."""

    label: str
    rate: tuple[int, int, int] | None
    measured: tuple[int, int, int]
    bounds: tuple[int, int, int]
    model: tuple[int, int, int]
    band: tuple[int, int, int]
    coef: dict[str, tuple[int, int, int]]


def _styles(axes: tuple[str, ...]) -> dict[str, _Style]:
    """Axis name ("" for a one-axis stream) -> its style. Several axes: each its
    AXIS_COLOURS colour, in shades (``_shades``) for its bounds, model and model band."""
    if not axes:
        return {"": _Style("", None, MEASURED_COLOUR, BOUNDS_COLOUR, MODEL_COLOUR, BAND_COLOUR, _COEF_COLORS)}
    out = {}
    for k, a in enumerate(axes):
        c = AXIS_COLOURS[k % len(AXIS_COLOURS)]
        out[a] = _Style(f"{a}: ", c, c, *_shades(c), dict.fromkeys(COEFFICIENTS, c))
    return out


def _shades(colour: tuple[int, int, int]) -> tuple[tuple[int, int, int], tuple[int, int, int], tuple[int, int, int]]:
    """An axis colour's shades for its confidence bounds (darker), model (lighter) and model band (greyed)."""
    return _mix(colour, (0, 0, 0), 0.45), _mix(colour, (255, 255, 255), 0.35), _mix(colour, (128, 128, 128), 0.6)


def _mix(colour: tuple[int, int, int], to: tuple[int, int, int], f: float) -> tuple[int, int, int]:
    """``colour`` moved a fraction ``f`` towards ``to``."""
    r, g, b = (round(c + f * (t - c)) for c, t in zip(colour, to, strict=True))
    return r, g, b


def aux_colour(k: int) -> tuple[int, int, int]:
    """The colour of the ``k``-th aux channel."""
    return AUX_COLOURS[k % len(AUX_COLOURS)]
