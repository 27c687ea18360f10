"""Denoising of gyro rate (docs/methods.md): steady-state Kalman filters for a static rate
(random-walk bias seen through white noise) and a dynamic rate (constant rate change
driven by white angular acceleration), and wavelet threshold denoising.

The Kalman filters run at their steady-state gain, which they reach within a few time
constants: a fixed linear recursion, so the whole record is filtered by scipy's lfilter
in C instead of a per-sample Python loop. Noise levels come from the IEEE-952
coefficients: measurement variance (60 N)^2 fs (deg/h)^2 per sample, random-walk step
variance (K/60)^2 / fs (deg/h)^2."""
from __future__ import annotations

import math

import numpy as np
import pywt
from scipy.linalg import solve_discrete_are
from scipy.signal import lfilter, lfilter_zi

from fogmon.errors import FogmonError


def static_gain(sample_rate_hz: float, N_dpsh: float, K_dphsh: float) -> tuple[float, float]:
    """Steady-state Kalman gain L and a-posteriori error variance P ((deg/h)^2) for
    x_k = x_{k-1} + w (var q), z_k = x_k + v (var r)."""
    r = (60.0 * N_dpsh) ** 2 * sample_rate_hz
    q = (K_dphsh / 60.0) ** 2 / sample_rate_hz
    if r <= 0 or q <= 0:
        raise FogmonError("kalman: N_dpsh and K_dphsh must both be > 0")
    p_pred = (q + math.sqrt(q * q + 4.0 * q * r)) / 2.0
    gain = p_pred / (p_pred + r)
    return gain, (1.0 - gain) * p_pred


def kalman_static(rate_dph, sample_rate_hz: float, N_dpsh: float, K_dphsh: float) -> np.ndarray:
    """Kalman estimate (deg/h) of a slowly wandering rate: x_k = x_{k-1} + L (z_k - x_{k-1}),
    started at the first sample."""
    z = np.asarray(rate_dph, float)
    gain, _ = static_gain(sample_rate_hz, N_dpsh, K_dphsh)
    b, a = [gain], [1.0, -(1.0 - gain)]
    out, _ = lfilter(b, a, z, zi=lfilter_zi(b, a) * z[0])
    return out


class StaticKalmanStream:
    """``kalman_static`` block by block, for a live channel: the same recursion with its
    state carried across blocks. An invalid (NaN) sample has no measurement: the estimate
    is held (the steady-state gain is kept, a small approximation after long gaps)."""

    def __init__(self, sample_rate_hz: float, N_dpsh: float, K_dphsh: float) -> None:
        self.gain, self.variance_dph2 = static_gain(sample_rate_hz, N_dpsh, K_dphsh)
        self._x = float("nan")  # the last estimate, deg/h

    def push(self, rate_dph) -> np.ndarray:
        """Estimates (deg/h) for one block of measurements (deg/h, NaN = none); NaN until
        the first measurement."""
        z = np.asarray(rate_dph, float)
        out = np.empty(len(z))
        b, a = [self.gain], [1.0, -(1.0 - self.gain)]
        ok = np.isfinite(z)
        edges = np.flatnonzero(np.diff(np.concatenate(([False], ok, [False])).astype(np.int8)))
        prev = 0
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            out[prev:start] = self._x
            x0 = z[start] if np.isnan(self._x) else self._x
            out[start:stop], _ = lfilter(b, a, z[start:stop], zi=[(1.0 - self.gain) * x0])
            self._x = float(out[stop - 1])
            prev = stop
        out[prev:] = self._x
        return out


def dynamic_gain(sample_rate_hz: float, N_dpsh: float, accel_dphps: float) -> np.ndarray:
    """Steady-state gain (2,) of the constant-rate-change filter: state (rate deg/h,
    rate change deg/h/s), white angular acceleration of spectral density
    ``accel_dphps`` (deg/h/s per sqrt(Hz)), rate measured with ARW N."""
    dt = 1.0 / sample_rate_hz
    F = np.array([[1.0, dt], [0.0, 1.0]])
    H = np.array([[1.0, 0.0]])
    qa = accel_dphps ** 2
    Q = qa * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    R = np.array([[(60.0 * N_dpsh) ** 2 * sample_rate_hz]])
    if R[0, 0] <= 0 or qa <= 0:
        raise FogmonError("kalman: N_dpsh and accel_dphps must both be > 0")
    P = solve_discrete_are(F.T, H.T, Q, R)  # a-priori covariance
    return (P @ H.T / (H @ P @ H.T + R)).ravel()


def kalman_dynamic(rate_dph, sample_rate_hz: float, N_dpsh: float, accel_dphps: float) -> np.ndarray:
    """Kalman estimate (deg/h) of a manoeuvring rate (steady-state constant-rate-change
    filter), as the equivalent second-order IIR filter from measurement to rate."""
    z = np.asarray(rate_dph, float)
    dt = 1.0 / sample_rate_hz
    L = dynamic_gain(sample_rate_hz, N_dpsh, accel_dphps)
    F = np.array([[1.0, dt], [0.0, 1.0]])
    A = (np.eye(2) - np.outer(L, [1.0, 0.0])) @ F  # x_k = A x_{k-1} + L z_k
    # transfer function z -> x_k[0]: b(q) / det(I - A q^-1)
    a = [1.0, -np.trace(A), np.linalg.det(A)]
    b = [L[0], A[0, 1] * L[1] - A[1, 1] * L[0]]
    out, _ = lfilter(b, a, z, zi=lfilter_zi(b, a) * z[0])
    return out


def wavelet_denoise(rate_dph, wavelet: str = "db4", level: int | None = None) -> np.ndarray:
    """Wavelet threshold denoising (deg/h): soft universal threshold sigma sqrt(2 ln n)
    on every detail level, sigma from the median absolute finest details / 0.6745."""
    y = np.asarray(rate_dph, float)
    w = pywt.Wavelet(wavelet)
    lmax = pywt.dwt_max_level(len(y), w.dec_len)
    coeffs = pywt.wavedec(y, w, level=lmax if level is None else min(level, lmax))
    sigma = np.median(np.abs(coeffs[-1])) / 0.6745
    thr = sigma * math.sqrt(2.0 * math.log(len(y)))
    coeffs = [coeffs[0]] + [pywt.threshold(c, thr, mode="soft") for c in coeffs[1:]]
    return pywt.waverec(coeffs, w)[: len(y)]
