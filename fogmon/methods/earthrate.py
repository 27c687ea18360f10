"""Up/down calibration of a single-axis gyro against Earth rate (DESIGN 4.7).

With the sensing axis pointing up and then down on a level, stationary base at
latitude phi, the true inputs are +/- w_e sin(phi). From the mean outputs (deg/h):
bias b = (I_up + I_down) / 2 and scale-factor error
S = (I_up - I_down - 2 w_e sin(phi)) / (2 w_e sin(phi))."""
from __future__ import annotations

import math

from fogmon.errors import FogmonError

#: Earth's sidereal rotation rate, deg/h.
EARTH_RATE_DPH = 15.041067


def updown_calibration(mean_up_dph: float, mean_down_dph: float, lat_deg: float,
                       std_of_mean_dph: float = 0.0) -> dict:
    """Bias (deg/h) and scale-factor error (ppm) from up/down mean outputs, with 1-sigma
    uncertainties when the standard deviation of each mean is given (deg/h; e.g. the
    Allan deviation at the averaging time)."""
    vertical = EARTH_RATE_DPH * math.sin(math.radians(lat_deg))
    if abs(vertical) < 1e-3:
        raise FogmonError(f"updown_calibration: latitude {lat_deg} deg is too close to the equator "
                          "(no vertical Earth rate to calibrate against)")
    bias = (mean_up_dph + mean_down_dph) / 2.0
    sf = (mean_up_dph - mean_down_dph - 2.0 * vertical) / (2.0 * vertical)
    s = std_of_mean_dph
    return {"bias_dph": bias, "bias_sigma_dph": s / math.sqrt(2.0),
            "scale_factor_ppm": sf * 1e6, "scale_factor_sigma_ppm": s * math.sqrt(2.0) / (2.0 * abs(vertical)) * 1e6,
            "earth_vertical_dph": vertical}
