"""Thermal-drift correction applied while the gyro runs, block by block.

The prediction is the ``thermal_drift`` effect that ``fogmon thermal`` calibrates
(fogmon.methods.thermal): K0(T) + K1 dT/dt + K2 d2T/dt2 on temperature smoothed by a
trailing moving average over ``smooth_s`` and differentiated by 3-point backward
differences with step ``diff_step_s``. Both filters look only backwards, so the live
correction needs no future sample: this class keeps the last ``smooth_s + 2 diff_step_s``
seconds of temperature and gives, sample for sample, what the offline
``correct_thermal`` gives on the whole record (equal to rounding once the tail holds
more than that span).

Samples whose temperature is unknown (NaN, e.g. lost samples) are left out of the
smoothing; a sample with no known temperature in its smoothing window gets a NaN
prediction and its corrected rate is NaN (the caller marks it invalid and counts it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fogmon.errors import FogmonError
from fogmon.sim.effects import backward_differences, thermal_drift_from
from fogmon.sim.model import Effect, SensorModel


@dataclass(frozen=True)
class Corrected:
    """One block after correction: ``rate_dph`` corrected (deg/h), ``drift_dph`` the
    prediction that was subtracted (deg/h), ``unknown`` where no temperature was known."""

    rate_dph: np.ndarray
    drift_dph: np.ndarray
    unknown: np.ndarray


def thermal_effect(model: SensorModel, name: str) -> Effect:
    """The model's one ``thermal_drift`` effect (a calibration file written by
    ``fogmon thermal --out-model``); FogmonError naming ``name`` otherwise."""
    found = [e for e in model.effects if e.kind == "thermal_drift"]
    if len(found) != 1:
        raise FogmonError(f"{name}: a thermal calibration needs exactly one [[effect]] with kind = "
                          f"\"thermal_drift\" (fogmon thermal --out-model writes it); found {len(found)}")
    return found[0]


class LiveThermalCorrection:
    """Causal thermal-drift correction of a stream of blocks (time s, rate deg/h,
    temperature deg C), carrying the filters' history from one block to the next."""

    def __init__(self, effect: Effect) -> None:
        self._params = effect.params
        self.smooth_s = float(self._params["smooth_s"])
        self.h_s = float(self._params["diff_step_s"])
        self.history_s = self.smooth_s + 2 * self.h_s
        self._t = np.empty(0)        # times of the kept history, s
        self._temp = np.empty(0)     # raw temperature, deg C (NaN = unknown)
        self._smooth = np.empty(0)   # smoothed temperature, deg C

    def _smoothed(self, t: np.ndarray, temp: np.ndarray, n_new: int) -> np.ndarray:
        """Trailing mean of the known temperatures in (t - smooth_s, t] for the last
        ``n_new`` of ``t`` (the history before them is included in ``t``/``temp``)."""
        new = slice(len(t) - n_new, len(t))
        if self.smooth_s <= 0:
            return temp[new].copy()
        known = np.isfinite(temp)
        ref = temp[known][0] if known.any() else 0.0
        c = np.concatenate(([0.0], np.cumsum(np.where(known, temp - ref, 0.0))))
        k = np.concatenate(([0], np.cumsum(known)))
        hi = np.arange(len(t) - n_new + 1, len(t) + 1)
        lo = np.searchsorted(t, t[new] - self.smooth_s, side="right")
        count = k[hi] - k[lo]
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(count > 0, ref + (c[hi] - c[lo]) / count, np.nan)

    def push(self, t_s: np.ndarray, rate_dph: np.ndarray, temp_c: np.ndarray) -> Corrected:
        """Correct one block (equal-length arrays, time increasing across calls)."""
        t_new = np.asarray(t_s, float)
        n = len(t_new)
        if n == 0:
            return Corrected(np.empty(0), np.empty(0), np.zeros(0, bool))
        t = np.concatenate((self._t, t_new))
        temp = np.concatenate((self._temp, np.asarray(temp_c, float)))
        smooth = np.concatenate((self._smooth, self._smoothed(t, temp, n)))
        ok = np.isfinite(smooth)
        ts = smooth[-n:]
        back1 = self._at(t, smooth, ok, t_new - self.h_s)
        back2 = self._at(t, smooth, ok, t_new - 2 * self.h_s)
        d1, d2 = backward_differences(ts, back1, back2, self.h_s)
        drift = thermal_drift_from(ts, d1, d2, self._params)
        keep = np.searchsorted(t, t[-1] - self.history_s, side="left")
        keep = max(keep - 1, 0)  # one sample before the span, for interpolation at its edge
        self._t, self._temp, self._smooth = t[keep:], temp[keep:], smooth[keep:]
        return Corrected(np.asarray(rate_dph, float) - drift, drift, ~np.isfinite(drift))

    @staticmethod
    def _at(t: np.ndarray, smooth: np.ndarray, ok: np.ndarray, when: np.ndarray) -> np.ndarray:
        """Smoothed temperature interpolated at times ``when`` over the known values
        (held at the first known value before it, as the offline filter holds the
        record's first sample)."""
        if not ok.any():
            return np.full(len(when), np.nan)
        return np.interp(when, t[ok], smooth[ok])
