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

Two things make the coefficients' intervals honest (validation/thermal_coverage.py):

- The smoothing and the difference step are part of the model, not only of its
  estimation: they decide which samples of a slowly settling ramp count as accelerating
  (K1_pos) or not (K1_neg). A fit with other filters than the ones that define the
  drift mixes the branches (a bundled chamber log's k1_neg 18 came out as 25.3 with the
  old fixed 10 s / 1 s). Not given, they are chosen from ``FILTER_STEPS_S`` by the least
  residual.
- The rate noise is not white: bias instability and rate random walk wander over the
  hours a ramp lasts, and a K1 is a rate offset over a ramp. The standard errors are
  those of the least-squares estimator under the residual's own IEEE-952 noise (white
  N, flicker B, random walk K, fitted to its Allan deviation; a term the record cannot
  resolve at its 95 % upper limit, so then the intervals are conservative).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from fogmon.errors import FogmonError
from fogmon.sim.effects import temperature_derivatives, thermal_drift
from fogmon.sim.model import Effect, validate_effect
from fogmon.sim.noise import flicker_taus

#: Candidate smoothing lengths and difference steps (s) when the caller gives none; only
#: steps of at least one sample, and pairs whose settling (smooth_s + 2 diff_step_s) is at
#: most MAX_SETTLE_FRACTION of the record, take part (smoothing may also be 0).
FILTER_STEPS_S = (0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)
MAX_SETTLE_FRACTION = 0.1
COEFFICIENT_NAMES = ("k1_pos", "k1_neg", "k2_pos", "k2_neg")


@dataclass(frozen=True)
class ThermalCalibration:
    """Fitted ``thermal_drift`` effect; 1-sigma standard errors of its coefficients (same
    keys; k0 errors as a list) under the residual noise; the residual rate std (deg/h per
    sample); the residual's fitted IEEE-952 levels (``N_dpsh``, ``B_dph``, ``K_dphsh``)
    and the 95 % upper limits of the slow ones it does not resolve (each error is the
    larger of those with one such term at its limit); the number of candidate filter
    pairs the filters were chosen from (1: given)."""

    effect: Effect
    stderr: dict
    residual_std_dph: float
    residual_noise: dict
    upper_limits: dict
    candidates: int = 1


def _rate_hz(t: np.ndarray) -> float:
    """Sample rate (Hz) of sample times t (s): the median step's."""
    return 1.0 / float(np.median(np.diff(t)))


def _design(ts, d1, d2, degree: int) -> np.ndarray:
    pos = d1 * d2 > 0
    cols = [ts ** i for i in range(degree + 1)]
    cols += [np.where(pos, d1, 0.0), np.where(pos, 0.0, d1), np.where(pos, d2, 0.0), np.where(pos, 0.0, d2)]
    return np.column_stack(cols)


def _lstsq(X, y):
    """(column scale, scaled solution, scaled estimator rows W = (Xs'Xs)^-1 Xs', residual)
    of y ~ X; columns that are all zero (a branch never visited) are left out (scale 0)."""
    scale = np.sqrt((X ** 2).mean(axis=0))
    live = scale > 0
    Xs = X[:, live] / scale[live]
    W = np.linalg.pinv(Xs.T @ Xs) @ Xs.T
    b = W @ y
    return scale, live, b, W, y - Xs @ b


def filter_candidates(duration_s: float, sample_rate_hz: float, smooth_s: float | None = None,
                      diff_step_s: float | None = None) -> list[tuple[float, float]]:
    """(smooth_s, diff_step_s) pairs tried for the values not given (see FILTER_STEPS_S)."""
    steps = [h for h in FILTER_STEPS_S if h * sample_rate_hz >= 1.0 - 1e-9]
    smooths = [smooth_s] if smooth_s is not None else [0.0, *steps]
    diffs = [diff_step_s] if diff_step_s is not None else steps
    return [(s, h) for s in smooths for h in diffs if s + 2 * h <= MAX_SETTLE_FRACTION * duration_s]


def choose_filters(t_s, rate_dph, temp_c, degree: int = 2, smooth_s: float | None = None,
                   diff_step_s: float | None = None, where: str = "the record") -> tuple[float, float, int]:
    """(smooth_s, diff_step_s, number of candidates): the given values, and for a value
    not given the candidate with the least residual of the thermal fit (all candidates
    fitted on the same samples)."""
    if smooth_s is not None and diff_step_s is not None:
        return smooth_s, diff_step_s, 1
    t, y, T = (np.asarray(a, float) for a in (t_s, rate_dph, temp_c))
    duration = float(t[-1] - t[0])
    pairs = filter_candidates(duration, _rate_hz(t), smooth_s, diff_step_s)
    if not pairs:
        raise FogmonError(f"{where}: a {duration:g} s record is too short to choose `smooth_s` and "
                          f"`diff_step_s` (their settling may take at most {MAX_SETTLE_FRACTION:g} of it); give both")
    skip = max(s + 2 * h for s, h in pairs)
    use = (t >= t[0] + skip) & np.isfinite(y) & np.isfinite(T)
    best = None
    for s, h in pairs:
        X = _design(*temperature_derivatives(t, T, s, h), degree)[use]
        rss = float(np.sum(np.square(_lstsq(X, y[use])[4])))
        if best is None or rss < best[0]:
            best = (rss, s, h)
    assert best is not None
    return best[1], best[2], len(pairs)


def calibrate_thermal(t_s, rate_dph, temp_c, degree: int = 2, smooth_s: float | None = None,
                      diff_step_s: float | None = None, skip_s: float | None = None,
                      where: str = "the record") -> ThermalCalibration:
    """Least-squares thermal model of a rate record (deg/h) against temperature (deg C).

    ``degree``: degree of the K0(T) polynomial (its constant term absorbs the bias).
    ``smooth_s``, ``diff_step_s``: the derivative filters (s); one not given is chosen by
    ``choose_filters``. ``skip_s``: leading seconds left out while the derivative filters
    fill (default smooth_s + 2 diff_step_s). A branch (K1/K2 pos or neg) the record never
    visits is fitted as 0 with an infinite standard error. ``where`` names the record in
    error messages (its file)."""
    t = np.asarray(t_s, float)
    y = np.asarray(rate_dph, float)
    T = np.asarray(temp_c, float)
    if not (len(t) == len(y) == len(T)):
        raise FogmonError(f"{where}: time, rate and temperature lengths differ")
    if len(t) < 2 or not t[-1] > t[0]:
        raise FogmonError(f"{where}: {len(t)} samples do not span any time")
    smooth_s, diff_step_s, n_candidates = choose_filters(t, y, T, degree, smooth_s, diff_step_s, where)
    skip = smooth_s + 2 * diff_step_s if skip_s is None else skip_s
    X = _design(*temperature_derivatives(t, T, smooth_s, diff_step_s), degree)
    use = (t >= t[0] + skip) & np.isfinite(y) & np.isfinite(T)
    X, yy = X[use], y[use]
    if len(yy) < X.shape[1] * 10:
        raise FogmonError(f"{where}: {len(yy)} usable samples are too few for {X.shape[1]} coefficients")
    scale, live, b, W, resid = _lstsq(X, yy)
    fs = _rate_hz(t)
    grid = np.round((t[use] - t[0]) * fs).astype(np.int64)
    noises = residual_noise(resid, grid, fs)
    variances = [estimator_variance(W, grid, fs, **levels) for levels in noises]
    beta = np.zeros(X.shape[1])
    se = np.full(X.shape[1], np.inf)
    beta[live] = b / scale[live]
    se[live] = np.sqrt(np.max(variances, axis=0)) / scale[live]
    k0 = [float(v) for v in beta[:degree + 1]]
    params = {"k0_poly_dph": k0, **{n: float(v) for n, v in zip(COEFFICIENT_NAMES, beta[degree + 1:], strict=True)},
              "smooth_s": float(smooth_s), "diff_step_s": float(diff_step_s)}
    stderr = {"k0_poly_dph": [float(v) for v in se[:degree + 1]],
              **{n: float(v) for n, v in zip(COEFFICIENT_NAMES, se[degree + 1:], strict=True)}}
    return ThermalCalibration(validate_effect("thermal_drift", params), stderr, float(np.std(resid)),
                              noises[0], {k: n[k] for n in noises[1:] for k in n if n[k] != noises[0][k]},
                              n_candidates)


def residual_noise(resid, grid, sample_rate_hz: float) -> list[dict]:
    """IEEE-952 levels ({"N_dpsh", "B_dph", "K_dphsh"}) of a residual rate (deg/h) at the
    sample indices ``grid``, from the fit of its Allan deviation: the fitted levels, then
    for each slow term (B, K) the record does not resolve the same with that term at its
    95 % upper limit (each limit is profiled over the other terms, so one at a time)."""
    from fogmon.davar.batch import oadev
    from fogmon.davar.fit import fit_noise

    if not np.any(resid):
        return [{"N_dpsh": 0.0, "B_dph": 0.0, "K_dphsh": 0.0}]
    x = np.full(int(grid[-1]) + 1, np.nan)
    x[grid] = resid
    fit = fit_noise(oadev(x, sample_rate_hz, taus="octave"))
    fitted = {"N_dpsh": float(fit.N_dpsh.value), "B_dph": float(fit.B_dph.value), "K_dphsh": float(fit.K_dphsh.value)}
    limits = [{**fitted, k: float(c.upper)} for k, c in (("B_dph", fit.B_dph), ("K_dphsh", fit.K_dphsh))
              if not c.identifiable]
    return [fitted, *limits]


def estimator_variance(W, grid, sample_rate_hz: float, N_dpsh: float, B_dph: float, K_dphsh: float) -> np.ndarray:
    """Variance of each row's sum sum_t W[j, t] e_t for rate noise e (deg/h) of white N
    (deg/sqrt(h)), flicker B (deg/h) and rate random walk K (deg/h/sqrt(h)) at the sample
    indices ``grid`` (gaps in between). Flicker is fogmon's own (``fogmon.sim.noise``: a
    sum of Gauss-Markov terms of variance B^2 ln 2 / pi, correlation times doubling up
    to 10x the record); the random walk starts at the first sample."""
    fs = float(sample_rate_hz)
    w = np.zeros((W.shape[0], int(grid[-1]) + 1))
    w[:, grid] = W
    sum_w2 = np.sum(W * W, axis=1)
    var = (60.0 * N_dpsh) ** 2 * fs * sum_w2
    if B_dph > 0:
        s2 = B_dph ** 2 * math.log(2.0) / math.pi
        for tc in flicker_taus(fs, 10.0 * w.shape[1] / fs):
            a = math.exp(-1.0 / (fs * tc))      # sum_st w_s w_t a^|s-t| = 2 sum_t w_t (AR(1) of w)_t - sum w^2
            var += s2 * (2.0 * np.sum(w * lfilter([1.0], [1.0, -a], w, axis=1), axis=1) - sum_w2)
    if K_dphsh > 0:
        tail = np.cumsum(w[:, ::-1], axis=1)[:, ::-1]     # cov of a walk from 0: step^2 min(s, t)
        var += (K_dphsh / 60.0) ** 2 / fs * np.sum(tail * tail, axis=1)
    return np.maximum(var, 0.0)


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
