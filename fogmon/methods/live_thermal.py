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

import math
from dataclasses import dataclass

import numpy as np

from fogmon.errors import FogmonError
from fogmon.sim.model import Effect, SensorModel


@dataclass(frozen=True)
class Corrected:
    """One block after correction: ``rate_dph`` corrected (deg/h), ``drift_dph`` the
    prediction that was subtracted (deg/h), ``unknown`` where no temperature was known."""

    rate_dph: np.ndarray
    drift_dph: np.ndarray
    unknown: np.ndarray


def thermal_effect(model: SensorModel, name: str) -> Effect:
    """The model's one ``thermal_drift`` effect (a calibration file: the ``out_model`` of
    ``fogmon thermal``); FogmonError naming ``name`` otherwise."""
    found = [e for e in model.effects if e.kind == "thermal_drift"]
    if len(found) != 1:
        raise FogmonError(f"{name}: a thermal calibration needs exactly one [[effect]] with kind = "
                          f"\"thermal_drift\" (fogmon thermal `out_model` writes it); found {len(found)}")
    return found[0]


def axis_thermal_effect(model: SensorModel, name: str, axis: str) -> Effect:
    """The ``thermal_drift`` effect acting on ``axis`` (its ``axes`` name it, or it has
    none: every axis) of a calibration file ``name``: what ``fogmon thermal`` (``out_model``)
    writes for a multi-axis recording, one effect per axis (docs/methods.md); a one-axis
    calibration serves every axis. FogmonError naming the file and axis otherwise."""
    found = [e for e in model.effects if e.kind == "thermal_drift" and (not e.axes or axis in e.axes)]
    if len(found) != 1:
        raise FogmonError(f"{name}: axis {axis}: a thermal calibration needs exactly one [[effect]] with kind = "
                          f"\"thermal_drift\" acting on the axis (axes = [\"{axis}\"], or no axes: every axis); "
                          f"found {len(found)}")
    return found[0]


class LiveThermalCorrection:
    """Causal thermal-drift correction of a stream of blocks (time s, rate deg/h,
    temperature deg C), carrying the filters' history from one block to the next. The
    trailing mean uses running prefix sums, and the history sits in a buffer trimmed only
    when full, so a block costs O(its length x log(history)), not O(history): a live
    1 kHz gyro delivers blocks of a few samples."""

    def __init__(self, effect: Effect) -> None:
        self._params = effect.params
        self.smooth_s = float(self._params["smooth_s"])
        self.h_s = float(self._params["diff_step_s"])
        self.history_s = self.smooth_s + 2 * self.h_s
        self._buf = np.empty((4, 0))   # rows: time s, prefix sum before, prefix count before, smoothed deg C
        self._n = 0                    # samples held in the buffer
        self._ref = math.nan           # temperature the prefix sums are taken from (the first known), deg C
        self._sum_next = 0.0           # prefix sum and count before the next sample
        self._count_next = 0

    def _append(self, cols: np.ndarray) -> None:
        """Add columns to the history; when the buffer is full, drop what is older than
        history_s (one sample before it kept, for interpolation) and grow if needed."""
        m = cols.shape[1]
        if self._n + m > self._buf.shape[1]:
            t = self._buf[0, :self._n]
            keep = max(int(np.searchsorted(t, t[-1] - self.history_s, side="left")) - 1, 0) if self._n else 0
            held = self._buf[:, keep:self._n]
            cap = max(2 * (held.shape[1] + m), 1024)
            self._buf = np.empty((4, cap))
            self._buf[:, :held.shape[1]] = held
            self._n = held.shape[1]
        self._buf[:, self._n:self._n + m] = cols
        self._n += m

    def _smoothed(self, t_new: np.ndarray, temp: np.ndarray) -> np.ndarray:
        """Trailing mean (deg C) of the known temperatures in (t - smooth_s, t] for each
        new sample, the new samples' columns appended to the history."""
        known = np.isfinite(temp)
        if math.isnan(self._ref) and known.any():
            self._ref = float(temp[known][0])
        ref = 0.0 if math.isnan(self._ref) else self._ref
        v = np.where(known, temp - ref, 0.0)
        before = self._sum_next + np.concatenate(([0.0], np.cumsum(v)[:-1]))
        count_before = self._count_next + np.concatenate(([0], np.cumsum(known)[:-1]))
        self._sum_next, self._count_next = float(before[-1] + v[-1]), int(count_before[-1] + known[-1])
        self._append(np.vstack((t_new, before, count_before, np.full(len(t_new), np.nan))))
        n, m = self._n, len(t_new)
        if self.smooth_s <= 0:
            smooth = temp.copy()
        else:
            t, pre, cnt = self._buf[0, :n], self._buf[1, :n], self._buf[2, :n]
            lo = np.searchsorted(t, t_new - self.smooth_s, side="right")
            total = pre[n - m:] + v - pre[lo]
            count = cnt[n - m:] + known - cnt[lo]
            with np.errstate(invalid="ignore", divide="ignore"):
                smooth = np.where(count > 0, ref + total / count, np.nan)
        # an unknown smoothed value holds the last known one for the differences
        last = self._buf[3, n - m - 1] if n > m else math.nan
        filled = smooth.copy()
        idx = np.where(np.isfinite(filled), np.arange(m), -1)
        np.maximum.accumulate(idx, out=idx)
        filled = np.where(idx >= 0, filled[np.maximum(idx, 0)], last)
        self._buf[3, n - m:n] = filled
        return smooth

    def push(self, t_s: np.ndarray, rate_dph: np.ndarray, temp_c: np.ndarray) -> Corrected:
        """Correct one block (equal-length arrays, time increasing across calls)."""
        # imported here: fogmon.sim.effects pulls in scipy.signal (a second of every run's start-up)
        from fogmon.sim.effects import backward_differences, thermal_drift_from

        t_new = np.asarray(t_s, float)
        if len(t_new) == 0:
            return Corrected(np.empty(0), np.empty(0), np.zeros(0, bool))
        ts = self._smoothed(t_new, np.asarray(temp_c, float))
        t, filled = self._buf[0, :self._n], self._buf[3, :self._n]
        a = max(int(np.searchsorted(t, t_new[0] - 2 * self.h_s, side="left")) - 1, 0)
        first = a + int(np.argmax(np.isfinite(filled[a:])))  # interpolation starts at a known value
        if not np.isfinite(filled[first]):
            drift = np.full(len(t_new), np.nan)
        else:
            # held at the first known value before it, as the offline filter holds the record's first sample
            back1 = np.interp(t_new - self.h_s, t[first:], filled[first:])
            back2 = np.interp(t_new - 2 * self.h_s, t[first:], filled[first:])
            d1, d2 = backward_differences(ts, back1, back2, self.h_s)
            drift = thermal_drift_from(ts, d1, d2, self._params)
        return Corrected(np.asarray(rate_dph, float) - drift, drift, ~np.isfinite(drift))
