"""Closed-form Allan deviations (tau in s, deviations in deg/h).

IEEE Std 952 model, with Q in arcsec, N in deg/sqrt(h), B in deg/h, K in deg/h/sqrt(h),
R in deg/h^2 (1 deg/h = 1 arcsec/s):
sigma^2(tau) = 3 Q^2/tau^2 + (60 N)^2/tau + (2 ln2/pi) B^2 + (K/60)^2 tau/3 + (R/3600)^2 tau^2/2.
"""
from __future__ import annotations

import numpy as np

FLICKER_FACTOR = 2.0 * np.log(2.0) / np.pi
"""sigma^2 = FLICKER_FACTOR * B^2 on the flicker floor (sigma = 0.664 B)."""

POWERS = np.array([-2, -1, 0, 1, 2])
"""Powers n of tau in sigma^2 = sum_n A_n tau^n, in the order Q, N, B, K, R."""


#: The IEEE-952 coefficients in the order of POWERS (n = -2..2), with their units.
NAMES = ("Q_arcsec", "N_dpsh", "B_dph", "K_dphsh", "R_dphh")


def coefficients_to_avar_terms(Q_arcsec=0.0, N_dpsh=0.0, B_dph=0.0, K_dphsh=0.0, R_dphh=0.0) -> np.ndarray:
    """IEEE-952 coefficients -> A_n (deg/h)^2 s^-n for n = -2..2 (last axis)."""
    return np.stack(np.broadcast_arrays(
        3.0 * np.square(Q_arcsec), np.square(60.0 * np.asarray(N_dpsh)), FLICKER_FACTOR * np.square(B_dph),
        np.square(np.asarray(K_dphsh) / 60.0) / 3.0, np.square(np.asarray(R_dphh) / 3600.0) / 2.0), axis=-1)


def avar_terms_to_coefficients(a: np.ndarray) -> np.ndarray:
    """Inverse of :func:`coefficients_to_avar_terms`: A_n (>= 0, last axis) -> (Q, N, B, K, R)."""
    a = np.maximum(np.asarray(a, dtype=np.float64), 0.0)
    return np.stack([np.sqrt(a[..., 0] / 3.0), np.sqrt(a[..., 1]) / 60.0, np.sqrt(a[..., 2] / FLICKER_FACTOR),
                     60.0 * np.sqrt(3.0 * a[..., 3]), 3600.0 * np.sqrt(2.0 * a[..., 4])], axis=-1)


def adev_model(tau_s, Q_arcsec=0.0, N_dpsh=0.0, B_dph=0.0, K_dphsh=0.0, R_dphh=0.0) -> np.ndarray:
    """IEEE-952 Allan deviation (deg/h) at ``tau_s`` (s) for the given coefficients."""
    tau = np.asarray(tau_s, dtype=np.float64)
    a = coefficients_to_avar_terms(Q_arcsec, N_dpsh, B_dph, K_dphsh, R_dphh)
    return np.sqrt(sum(a[..., i] * tau ** float(p) for i, p in enumerate(POWERS)))


def markov_adev(tau_s, sigma_dph: float, tau_c_s: float) -> np.ndarray:
    """Allan deviation (deg/h) of a first-order Gauss-Markov rate with stationary std
    ``sigma_dph`` (deg/h) and correlation time ``tau_c_s`` (s); peak 0.618 sigma at
    tau = 1.89 tau_c (IEEE-952 C.4)."""
    x = np.asarray(tau_s, dtype=np.float64) / tau_c_s
    avar = sigma_dph**2 / x**2 * (2.0 * x - 3.0 + 4.0 * np.exp(-x) - np.exp(-2.0 * x))
    return np.sqrt(avar)


def sinusoid_adev(tau_s, amplitude_dph: float, period_s: float) -> np.ndarray:
    """Allan deviation (deg/h) of a sinusoidal rate of amplitude ``amplitude_dph`` (deg/h)
    and period ``period_s`` (s): A sin^2(pi f0 tau) / (pi f0 tau); peak 0.725 A at
    tau = 0.371 period."""
    x = np.pi * np.asarray(tau_s, dtype=np.float64) / period_s
    return abs(amplitude_dph) * np.sin(x) ** 2 / x
