"""Up/down calibration of a single-axis gyro against Earth rate (docs/methods.md).

With the sensing axis pointing up and then down on a level, stationary base at
latitude phi, the true inputs are +/- w_e sin(phi). From the mean outputs (deg/h):
bias b = (I_up + I_down) / 2 and scale-factor error
S = (I_up - I_down - 2 w_e sin(phi)) / (2 w_e sin(phi)).

What cannot give a scale factor is refused with the reason: a latitude outside
-90..90 deg; a site so close to the equator that the vertical Earth rate is small
against the uncertainty of the means (1-sigma of S above MAX_SF_SIGMA); and means
whose S would be MAX_SF or more, which is a setup mistake, not a gyro property (swapped
recordings give S near -200 %, the same orientation twice -100 %)."""
from __future__ import annotations

import math

from fogmon.errors import FogmonError

#: Earth's sidereal rotation rate, deg/h.
EARTH_RATE_DPH = 15.041067
#: Largest 1-sigma uncertainty of the scale-factor error worth reporting (10 %).
MAX_SF_SIGMA = 0.1
#: A scale-factor error this large (50 %) is a setup mistake, not a gyro property.
MAX_SF = 0.5


def check_latitude(lat_deg: float) -> float:
    """``lat_deg`` if it is a latitude (finite, -90..90 deg), else a FogmonError."""
    if not (math.isfinite(lat_deg) and -90.0 <= lat_deg <= 90.0):
        raise FogmonError(f"latitude {lat_deg:g} deg is not within -90..90 deg (south is negative)")
    return lat_deg


def updown_calibration(mean_up_dph: float, mean_down_dph: float, lat_deg: float,
                       std_of_mean_dph: float = 0.0, names: tuple[str, str] = ("up", "down")) -> dict:
    """Bias (deg/h) and scale-factor error (ppm) from up/down mean outputs, with 1-sigma
    uncertainties when the standard deviation of each mean is given (deg/h; e.g. the
    Allan deviation at the averaging time). ``names`` label the two records in errors."""
    vertical = EARTH_RATE_DPH * math.sin(math.radians(check_latitude(lat_deg)))
    s = std_of_mean_dph
    if not vertical:
        raise FogmonError(f"at latitude {lat_deg:g} deg (the equator) Earth rate has no vertical component: "
                          f"no scale factor can be calibrated up/down there")
    sf_sigma = s * math.sqrt(2.0) / (2.0 * abs(vertical))
    if sf_sigma > MAX_SF_SIGMA:
        raise FogmonError(f"at latitude {lat_deg:g} deg the vertical Earth rate is {vertical:.3g} deg/h, too small "
                          f"against the {s:.3g} deg/h uncertainty of each mean: the scale-factor error would be "
                          f"uncertain by {100 * sf_sigma:.3g} % (more than {100 * MAX_SF_SIGMA:g} %); record longer "
                          f"or farther from the equator")
    diff, expected = mean_up_dph - mean_down_dph, 2.0 * vertical
    sf = (diff - expected) / expected
    if abs(sf) >= MAX_SF:
        why = (f"{names[0]} and {names[1]} look swapped (or the latitude's sign is wrong: south is negative)"
               if diff / expected < 0 else
               f"{names[0]} and {names[1]} differ by far less than Earth rate (the same orientation twice?)"
               if abs(diff) < abs(expected) else
               f"{names[0]} and {names[1]} differ by far more than Earth rate (a wrong latitude? rates not in deg/h?)")
        raise FogmonError(f"{why}: up - down = {diff:+.4g} deg/h where a gyro within {100 * MAX_SF:g} % of its scale "
                          f"factor reads {expected:+.4g} deg/h (2 x the vertical Earth rate at latitude "
                          f"{lat_deg:g} deg)")
    return {"bias_dph": (mean_up_dph + mean_down_dph) / 2.0, "bias_sigma_dph": s / math.sqrt(2.0),
            "scale_factor_ppm": sf * 1e6, "scale_factor_sigma_ppm": sf_sigma * 1e6,
            "earth_vertical_dph": vertical}
