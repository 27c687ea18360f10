"""Angular units -> deg/h: the one table every decoder (KVH binary, DSP-3000, ASCII lines,
CAN) converts with; acceleration units -> g (accelerometers fogmon passes on are in g);
the unit of each noise coefficient from its name's suffix: a gyro's IEEE Std 952 terms
and an accelerometer's IEEE Std 1293 terms, with the factors between the two."""
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
#: acceleration unit -> g per unit (an accelerometer channel's unit, e.g. an MDF4 file's)
G_PER_UNIT: dict[str, float] = {"g": 1.0, "mg": 1e-3, "ug": 1e-6, "m/s^2": 1.0 / G0_MPS2,
                                "ft/s^2": 0.3048 / G0_MPS2}
#: other spellings of the same acceleration units
ACCEL_ALIASES = {"m/s2": "m/s^2", "m/s²": "m/s^2", "m/s/s": "m/s^2", "mps2": "m/s^2", "µg": "ug",
                 "ft/s2": "ft/s^2", "ft/s²": "ft/s^2"}
#: micro-g per g: accelerations enter the Allan-deviation engines and the fit in micro-g, so
#: their numbers lie in the range of a gyro's deg/h (the engines are unit-agnostic)
UG_PER_G = 1e6

#: coefficient-name suffix -> its unit (fogmon.davar.fit.NAMES: Q_arcsec, N_dpsh, ...;
#: ACCEL_NAMES: Q_mps, VRW_mpsph, ...)
SUFFIX_UNITS = {"arcsec": "arcsec", "dpsh": "deg/sqrt(h)", "dph": "deg/h", "dphsh": "deg/h/sqrt(h)",
                "dphh": "deg/h^2", "mps": "m/s", "mpsph": "m/s/sqrt(h)", "ug": "ug",
                "mpshsh": "m/s/h/sqrt(h)", "mpshh": "m/s/h^2"}

#: An accelerometer's noise coefficients (IEEE Std 1293), in the order of the gyro's Q, N,
#: B, K, R: velocity quantization (m/s), velocity random walk (m/s/sqrt(h)), bias
#: instability (micro-g), acceleration random walk (m/s/h/sqrt(h)), acceleration ramp
#: (m/s/h^2). Allan variance of the acceleration a (m/s^2):
#: 3 Q^2/tau^2 + (VRW/60)^2/tau + (2 ln2/pi) (Bias g0 1e-6)^2 + (AccRW/216000)^2 tau/3 + (Ramp/3600^2)^2 tau^2/2.
ACCEL_NAMES = ("Q_mps", "VRW_mpsph", "Bias_ug", "AccRW_mpshsh", "Ramp_mpshh")
#: The same fit's accelerometer coefficient per gyro-named coefficient when the fitted
#: curve is in micro-g (the IEEE-952 formulas read deg/h as micro-g): Q arcsec = ug s ->
#: m/s (x 1e-6 g0); N deg/sqrt(h) = ug sqrt(s) / 60 -> m/s/sqrt(h) (x 3600e-6 g0); B
#: unchanged; K deg/h/sqrt(h) = 60 ug/sqrt(s) -> m/s/h/sqrt(h) (x 3600e-6 g0, since
#: 1 m/s^2.5 = 216000 m/s/h/sqrt(h)); R deg/h^2 = 3600 ug/s -> m/s/h^2 (x 3600e-6 g0).
ACCEL_PER_GYRO: dict[str, tuple[str, float]] = {
    "Q_arcsec": ("Q_mps", 1e-6 * G0_MPS2), "N_dpsh": ("VRW_mpsph", 3600e-6 * G0_MPS2), "B_dph": ("Bias_ug", 1.0),
    "K_dphsh": ("AccRW_mpshsh", 3600e-6 * G0_MPS2), "R_dphh": ("Ramp_mpshh", 3600e-6 * G0_MPS2)}


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


def g_per_unit(unit: str) -> float | None:
    """g per unit of the acceleration unit ``unit`` (case and spaces ignored, aliases
    read), None if unknown."""
    key = unit.strip().replace(" ", "")
    key = ACCEL_ALIASES.get(key, key)
    low = key.lower()
    return G_PER_UNIT.get(key) if key in G_PER_UNIT else G_PER_UNIT.get(low)


def coefficient_unit(name: str) -> str:
    """The unit of a noise coefficient from its name's suffix (Q_arcsec -> arcsec, VRW_mpsph -> m/s/sqrt(h))."""
    return SUFFIX_UNITS[name.rsplit("_", 1)[1]]
