"""The physics table of ``aux_response`` (docs/explain.md, "Laws outside the catalogue"):
what a fitted term means, from its feature's shape (fogmon.sim.features) and the kind of
channel it reads (fogmon.units.channel_unit: the column name's suffix or the
recording's ``unit_<column>`` line). A term the table does not know gets no physics
name: the report says "bias follows <feature>, <coef> <unit>" and invents nothing."""
from __future__ import annotations

from fogmon.sim.features import Feature, other_axis
from fogmon.units import channel_unit

#: (shape, quantity of the channel) -> physics. "another axis's rate" is a rate column
#: of another axis (rate_x_dph); "angular rate" the reference rotation about the sensing
#: axis (rot_dps) or any other angular-rate channel.
PHYSICS: dict[tuple[str, str], str] = {
    ("linear", "acceleration"): "g-sensitivity",
    ("abs", "acceleration"): "g-sensitivity",
    ("square", "acceleration"): "vibration rectification",
    ("product", "acceleration"): "vibration rectification",
    ("linear", "magnetic field"): "magnetic (Faraday) sensitivity",
    ("abs", "magnetic field"): "magnetic (Faraday) sensitivity",
    ("square", "magnetic field"): "magnetic (Faraday) sensitivity",
    ("rate", "temperature"): "thermal transient (Shupe)",
    ("linear", "temperature"): "temperature sensitivity",
    ("square", "temperature"): "temperature sensitivity",
    ("linear", "another axis's rate"): "cross-coupling / misalignment",
    ("abs", "another axis's rate"): "cross-axis rate rectification",
    ("abs", "angular rate"): "scale-factor asymmetry",
    ("linear", "voltage"): "supply sensitivity",
    ("square", "voltage"): "supply sensitivity",
    ("abs", "voltage"): "supply sensitivity",
}


def quantity(name: str, meta: dict | None = None) -> str:
    """The kind of channel ``name`` is: "another axis's rate" for a rate column, else its
    quantity from ``channel_unit`` ("" when its name and the header do not say)."""
    if other_axis(name) is not None:
        return "another axis's rate"
    return channel_unit(name, meta)[0]


def physics_of(f: Feature, meta: dict | None = None) -> str:
    """The physics name of a term on feature ``f`` (PHYSICS), "" when the table does not
    know it; a product is named only when both channels are of one quantity the table
    names for products."""
    kinds = {quantity(n, meta) for n in f.names}
    if len(kinds) != 1:
        return ""
    return PHYSICS.get((f.shape, kinds.pop()), "")

