"""The plausibility gate: a rate no gyro of the kind can report is a corrupt sample
(a garbage float in a CRC-valid frame, a mangled ASCII line, a typo in a log), never data.

Every decoder and reader passes its rates through ``gate`` with the device's measurement
range plus a margin; what falls outside becomes an invalid sample (rate NaN, so the engines
drop exactly the Allan terms that span it) and is counted as ``implausible_samples``.
Ranges are datasheet full scale x ``MARGIN``; ``max_rate_dph`` overrides them. KVH
frames also carry a temperature: a reading outside ``TEMP_RANGE_C`` becomes NaN and is
counted as ``implausible_temp_c``.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from fogmon.errors import FogmonError

#: full scale x MARGIN is the gate: a saturated gyro still reads inside it
MARGIN = 1.5
#: KVH DSP-1750 / 1760 / 1775 input range +-490 deg/s (datasheets), in deg/h
KVH_DSP17XX_FULL_SCALE_DPH = 490.0 * 3600.0
#: KVH DSP-3000 input range +-375 deg/s (datasheet), in deg/h
KVH_DSP3000_FULL_SCALE_DPH = 375.0 * 3600.0
#: the gates (deg/h) of the KVH devices
KVH_DSP17XX_MAX_ABS_DPH = KVH_DSP17XX_FULL_SCALE_DPH * MARGIN
KVH_DSP3000_MAX_ABS_DPH = KVH_DSP3000_FULL_SCALE_DPH * MARGIN
#: devices fogmon knows nothing about (ASCII lines, CAN, replay logs): 10,000 deg/s in
#: deg/h, beyond the full scale of any gyro made (MEMS parts stop at +-4000 deg/s)
GENERIC_MAX_ABS_DPH = 10_000.0 * 3600.0
#: the counter every gated source reports
COUNTER = "implausible_samples"
#: temperatures (deg C) a working gyro can report: wider than any FOG's operating and
#: storage range; beyond it the field is corrupt, not a temperature
TEMP_RANGE_C = (-60.0, 125.0)
#: the counter of the KVH decoders for temperatures outside TEMP_RANGE_C
TEMP_COUNTER = "implausible_temp_c"
#: accelerations (g) a KVH DSP-17xx accelerometer can report: well beyond the range of any
#: of them (+-10 g on the DSP-1750); beyond it the field is corrupt (a garbage float)
KVH_ACCEL_MAX_ABS_G = 50.0
#: the counter of the KVH decoders for accelerations beyond KVH_ACCEL_MAX_ABS_G (or not a number)
ACCEL_COUNTER = "implausible_accel_g"


def gate(rate_dph: ArrayLike, max_abs_dph: float, valid: ArrayLike | None = None) -> tuple[np.ndarray, int]:
    """``rate_dph`` (deg/h) with every value beyond +-``max_abs_dph`` replaced by NaN, and
    how many samples were implausible. Without ``valid`` only finite values beyond the
    range count (NaN is already an invalid sample); with ``valid`` (what the device
    flagged good) a valid sample that is NaN or inf counts too: a device that calls a
    non-number good sent garbage. The input is returned unchanged (not copied) when no
    value is replaced."""
    rate = np.asarray(rate_dph, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        ok = np.abs(rate) <= max_abs_dph          # NaN compares False
    bad = ~ok & ~np.isnan(rate)                   # to replace: inf and beyond the range
    n = int(np.count_nonzero(bad if valid is None else ~ok & np.asarray(valid, dtype=bool)))
    if not bad.any():
        return rate, n
    out = rate.copy()
    out[bad] = np.nan
    return out, n


def max_rate_dph(value: float | None, default_dph: float) -> float:
    """The gate (deg/h) of a decoder: ``value`` (the option ``max_rate_dph``, or a capture
    sidecar's ``max_rate_dph``) when given, else the device's ``default_dph``. A value
    that is not a finite number > 0 is a FogmonError. (A gate above the DAVAR engine's
    ceiling, ``davar.kernels.CEILING_DPH``, lets through samples that make the Allan terms
    spanning them +inf.)"""
    if value is None:
        return float(default_dph)
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise FogmonError(f"`max_rate_dph` must be a finite number > 0 deg/h, got {value!r}")
    return v
