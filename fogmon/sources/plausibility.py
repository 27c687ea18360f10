"""The plausibility gate: a rate no gyro of the kind can report is a corrupt sample
(a garbage float in a CRC-valid frame, a mangled ASCII line, a typo in a log), never data.

Every decoder and reader passes its rates through ``gate`` with the device's measurement
range plus a margin; what falls outside becomes an invalid sample (rate NaN, so the engines
drop exactly the Allan terms that span it) and is counted as ``implausible_samples``.
Ranges are datasheet full scale x ``MARGIN``; ``--max-rate-dph`` overrides them.
"""
from __future__ import annotations

import numpy as np

#: full scale x MARGIN is the gate: a saturated gyro still reads inside it
MARGIN = 1.5
#: KVH DSP-1750 / 1760 / 1775 input range +-490 deg/s (datasheets), in deg/h
KVH_DSP17XX_FULL_SCALE_DPH = 490.0 * 3600.0
#: KVH DSP-3000 input range +-375 deg/s (datasheet), in deg/h
KVH_DSP3000_FULL_SCALE_DPH = 375.0 * 3600.0
#: devices fogmon knows nothing about (ASCII lines, CAN, replay logs): 10,000 deg/s in
#: deg/h, beyond the full scale of any gyro made (MEMS parts stop at +-4000 deg/s)
GENERIC_MAX_ABS_DPH = 10_000.0 * 3600.0
#: the counter every gated source reports
COUNTER = "implausible_samples"


def gate(rate_dph: np.ndarray, max_abs_dph: float) -> tuple[np.ndarray, int]:
    """``rate_dph`` (deg/h) with every finite value beyond +-``max_abs_dph`` replaced by
    NaN, and how many were replaced. The input is returned unchanged (not copied) when
    every value is plausible."""
    rate = np.asarray(rate_dph, dtype=np.float64)
    bad = np.abs(rate) > max_abs_dph          # NaN compares False: already invalid
    n = int(np.count_nonzero(bad))
    if not n:
        return rate, 0
    out = rate.copy()
    out[bad] = np.nan
    return out, n

