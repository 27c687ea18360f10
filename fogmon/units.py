"""Angular units -> deg/h: the one table every decoder (KVH binary, DSP-3000, ASCII lines,
CAN) converts with, the unit of each IEEE-952 coefficient from its name's suffix, and
standard gravity (accelerometers in m/s^2 -> g)."""
from __future__ import annotations

import math

import numpy as np

_RAD_DEG = 180.0 / math.pi
#: unit -> (kind, deg/h per unit): kind "rate" = units/s (or /h), "delta" = angle per sample
#: (deg/h per unit per s of sample period; multiplied by the sample rate in Hz).
DPH_PER_UNIT: dict[str, tuple[str, float]] = {
    "deg/h": ("rate", 1.0), "deg/s": ("rate", 3600.0), "rad/s": ("rate", 3600.0 * _RAD_DEG),
    "deg": ("delta", 3600.0), "rad": ("delta", 3600.0 * _RAD_DEG), "arcsec": ("delta", 1.0),
}
#: other spellings of the same units (DBC files write dph, degree signs, ...)
ALIASES = {"dph": "deg/h", "°/h": "deg/h", "dps": "deg/s", "°/s": "deg/s", "°": "deg"}

#: standard gravity, m/s^2 per g (accelerometers fogmon passes on are in g)
G0_MPS2 = 9.80665

#: coefficient-name suffix -> its unit (fogmon.davar.fit.NAMES: Q_arcsec, N_dpsh, ...)
SUFFIX_UNITS = {"arcsec": "arcsec", "dpsh": "deg/sqrt(h)", "dph": "deg/h", "dphsh": "deg/h/sqrt(h)",
                "dphh": "deg/h^2"}


def canonical(unit: str) -> str | None:
    """The table's name of ``unit`` (case, spaces and aliases ignored), None if unknown."""
    key = unit.strip().lower().replace(" ", "")
    key = ALIASES.get(key, key)
    return key if key in DPH_PER_UNIT else None


def dph_scale(unit: str, sample_rate_hz: float) -> float:
    """deg/h per unit of ``unit`` (a name of DPH_PER_UNIT); a per-sample angle is scaled
    by the sample rate ``sample_rate_hz`` (Hz)."""
    kind, dph = DPH_PER_UNIT[unit]
    return dph * sample_rate_hz if kind == "delta" else dph


def to_dph(value, unit: str, sample_rate_hz: float) -> np.ndarray:
    """Values in ``unit`` (a name of DPH_PER_UNIT) -> deg/h (float64); a value too large
    for float64 becomes inf (gated as implausible afterwards), silently."""
    with np.errstate(over="ignore"):
        return np.asarray(value, dtype=np.float64) * dph_scale(unit, sample_rate_hz)


def coefficient_unit(name: str) -> str:
    """The unit of an IEEE-952 coefficient from its name's suffix (Q_arcsec -> arcsec)."""
    return SUFFIX_UNITS[name.rsplit("_", 1)[1]]


#: aux column-name suffix (lower case) -> (quantity, unit): what a channel measures, read
#: from its name (docs/formats.md: "carried along in the units its name says"); a
#: recording's ``unit_<column>`` metadata line overrides it (``channel_unit``)
CHANNEL_SUFFIXES: dict[str, tuple[str, str]] = {
    "g": ("acceleration", "g"), "mps2": ("acceleration", "m/s^2"),
    "c": ("temperature", "degC"), "degc": ("temperature", "degC"), "k": ("temperature", "K"),
    "dps": ("angular rate", "deg/s"), "dph": ("angular rate", "deg/h"), "radps": ("angular rate", "rad/s"),
    "rpm": ("angular rate", "rpm"),
    "v": ("voltage", "V"), "mv": ("voltage", "mV"), "a": ("current", "A"), "ma": ("current", "mA"),
    "ut": ("magnetic field", "uT"), "nt": ("magnetic field", "nT"), "mt": ("magnetic field", "mT"),
    "gauss": ("magnetic field", "gauss"), "mgauss": ("magnetic field", "mgauss"),
    "m": ("length", "m"), "pa": ("pressure", "Pa"), "hpa": ("pressure", "hPa"), "kpa": ("pressure", "kPa"),
    "hz": ("frequency", "Hz"), "s": ("time", "s"), "pct": ("fraction", "%"),
}
#: units (lower case) a ``unit_<column>`` metadata line may name -> quantity
UNIT_QUANTITIES = {u.lower(): q for q, u in CHANNEL_SUFFIXES.values()}


def channel_unit(name: str, meta: dict | None = None) -> tuple[str, str]:
    """(quantity, unit) of the aux column ``name``: a ``unit_<name>`` metadata entry of its
    recording (``meta``) when present, else its name's suffix after the last ``_``
    (CHANNEL_SUFFIXES: ``vib_g`` -> acceleration in g, ``mag_ut`` -> magnetic field in uT);
    ("", "") when neither says. A rate column of another axis (``rate_x_dph``) is an
    angular rate in deg/h."""
    given = (meta or {}).get(f"unit_{name}")
    if given:
        return UNIT_QUANTITIES.get(given.strip().lower(), ""), given.strip()
    if "_" in name:
        return CHANNEL_SUFFIXES.get(name.rsplit("_", 1)[1].lower(), ("", ""))
    return "", ""
