"""Thermal-drift prediction and correction (docs/methods.md, the thermal paper):
drift = K0(T) + K1(dT/dt) dT/dt + K2(d2T/dt2) d2T/dt2, with separate K1, K2 while the
temperature change accelerates (dT/dt * d2T/dt2 > 0) and decelerates (<= 0),
derivatives by 3-point backward differences on smoothed temperature.

Calibration is one least-squares fit of all coefficients on a chamber run (plateaus fix
K0(T), ramps fix K1 and K2); the result is a ``thermal_drift`` effect of the sensor
model (docs/formats.md), so prediction is the simulator's own effect function and the
calibration can be written into a model file. Prediction is causal (trailing smoothing,
backward differences): ``correct`` can run on a live stream given the temperature
history of the last ``smooth_s + 2 diff_step_s`` seconds.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fogmon.errors import FogmonError
from fogmon.sim.effects import temperature_derivatives, thermal_drift
from fogmon.sim.model import Effect, validate_effect


@dataclass(frozen=True)
class ThermalCalibration:
    """Fitted ``thermal_drift`` effect, 1-sigma standard errors of its coefficients
    (same keys; k0 errors as a list), and the residual rate std (deg/h)."""

    effect: Effect
    stderr: dict
    residual_std_dph: float


def _design(t_s, temp_c, degree: int, smooth_s: float, diff_step_s: float):
    ts, d1, d2 = temperature_derivatives(t_s, temp_c, smooth_s, diff_step_s)
    pos = d1 * d2 > 0
    cols = [ts ** i for i in range(degree + 1)]
    cols += [np.where(pos, d1, 0.0), np.where(pos, 0.0, d1), np.where(pos, d2, 0.0), np.where(pos, 0.0, d2)]
    return np.column_stack(cols)


def calibrate_thermal(t_s, rate_dph, temp_c, degree: int = 2, smooth_s: float = 10.0,
                      diff_step_s: float = 1.0, skip_s: float | None = None) -> ThermalCalibration:
    """Least-squares thermal model of a rate record (deg/h) against temperature (deg C).

    ``degree``: degree of the K0(T) polynomial (its constant term absorbs the bias).
    ``skip_s``: leading seconds left out while the derivative filters fill (default
    smooth_s + 2 diff_step_s). A branch (K1/K2 pos or neg) the record never visits is
    fitted as 0 with an infinite standard error."""
    t = np.asarray(t_s, float)
    y = np.asarray(rate_dph, float)
    T = np.asarray(temp_c, float)
    if not (len(t) == len(y) == len(T)):
        raise FogmonError("calibrate_thermal: time, rate and temperature lengths differ")
    skip = smooth_s + 2 * diff_step_s if skip_s is None else skip_s
    X = _design(t, T, degree, smooth_s, diff_step_s)
    use = (t >= t[0] + skip) & np.isfinite(y) & np.isfinite(T)
    X, yy = X[use], y[use]
    if len(yy) < X.shape[1] * 10:
        raise FogmonError(f"calibrate_thermal: {len(yy)} usable samples are too few for {X.shape[1]} coefficients")
    scale = np.sqrt((X ** 2).mean(axis=0))
    live = scale > 0
    beta = np.zeros(X.shape[1])
    se = np.full(X.shape[1], np.inf)
    Xs = X[:, live] / scale[live]
    b, *_ = np.linalg.lstsq(Xs, yy, rcond=None)
    resid = yy - Xs @ b
    dof = max(len(yy) - Xs.shape[1], 1)
    s2 = float(resid @ resid) / dof
    cov = s2 * np.linalg.pinv(Xs.T @ Xs)
    beta[live] = b / scale[live]
    se[live] = np.sqrt(np.diag(cov)) / scale[live]
    k0 = [float(v) for v in beta[:degree + 1]]
    names = ("k1_pos", "k1_neg", "k2_pos", "k2_neg")
    params = {"k0_poly_dph": k0, **{n: float(v) for n, v in zip(names, beta[degree + 1:], strict=True)},
              "smooth_s": float(smooth_s), "diff_step_s": float(diff_step_s)}
    stderr = {"k0_poly_dph": [float(v) for v in se[:degree + 1]],
              **{n: float(v) for n, v in zip(names, se[degree + 1:], strict=True)}}
    return ThermalCalibration(validate_effect("thermal_drift", params), stderr, float(np.sqrt(s2)))


def predict_thermal(t_s, temp_c, effect: Effect) -> np.ndarray:
    """Predicted thermal drift (deg/h) of a ``thermal_drift`` effect."""
    return thermal_drift(np.asarray(t_s, float), {"temp_c": np.asarray(temp_c, float)}, effect.params)


def correct_thermal(t_s, rate_dph, temp_c, effect: Effect) -> np.ndarray:
    """Rate (deg/h) with the predicted thermal drift removed."""
    return np.asarray(rate_dph, float) - predict_thermal(t_s, temp_c, effect)


def drift_peak_to_peak(t_s, rate_dph, average_s: float) -> float:
    """Peak-to-peak (deg/h) of the rate averaged over consecutive ``average_s`` blocks:
    the drift figure the thermal paper reports (1.68 -> 0.19 deg/h in its chamber test)."""
    t = np.asarray(t_s, float)
    y = np.asarray(rate_dph, float)
    k = np.floor((t - t[0]) / average_s).astype(np.int64)
    n = np.bincount(k)
    full = n >= max(1, int(0.9 * n.max()))
    means = np.bincount(k, weights=y)[full] / n[full]
    return float(means.max() - means.min())
