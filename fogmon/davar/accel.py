"""Accelerometer noise coefficients (IEEE Std 1293) from the gyro engines.

The Allan-deviation engines and the IEEE-952 fit (fogmon.davar.fit) work on numbers: the
five terms sigma^2(tau) = sum_n A_n tau^n describe an accelerometer's Allan variance as
they describe a gyro's. An acceleration enters them in micro-g (``to_ug``), and the fit's
coefficients, computed with the gyro formulas, convert by one factor per term
(fogmon.units.ACCEL_PER_GYRO) into velocity quantization Q_mps (m/s), velocity random walk
VRW_mpsph (m/s/sqrt(h)), bias instability Bias_ug (micro-g), acceleration random walk
AccRW_mpshsh (m/s/h/sqrt(h)) and acceleration ramp Ramp_mpshh (m/s/h^2): values,
intervals, identifiability and 95 % upper limits alike (each is a positive multiple of
the gyro-named one). Nothing of the fit changes; ``AccelFit.noise`` is the fit itself.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fogmon.davar.fit import Coefficient, NoiseFit, fit_noise
from fogmon.davar.result import CONFIDENCE, AdevResult, DadevResult
from fogmon.units import ACCEL_NAMES, ACCEL_PER_GYRO, UG_PER_G


def to_ug(accel_g) -> np.ndarray:
    """Acceleration in g -> micro-g (float64), what the engines take for an accelerometer."""
    return np.asarray(accel_g, dtype=np.float64) * UG_PER_G


def _scaled(c: Coefficient, f: float) -> Coefficient:
    return Coefficient(c.value * f, c.lo * f, c.hi * f, c.identifiable, c.upper * f)


@dataclass(frozen=True)
class AccelFit:
    """An accelerometer's fitted IEEE Std 1293 coefficients (units in the names, see
    fogmon.units.ACCEL_NAMES), each a fogmon.davar.fit.Coefficient as a gyro's (scalars
    for a whole-record fit, arrays over windows for a DADEV fit), and ``noise``: the
    IEEE-952 fit of the Allan deviation in micro-g they come from (its ``model_adev_dph``
    gives micro-g, its ``misfit`` and ``worst_ratio`` hold as they are)."""

    Q_mps: Coefficient
    VRW_mpsph: Coefficient
    Bias_ug: Coefficient
    AccRW_mpshsh: Coefficient
    Ramp_mpshh: Coefficient
    noise: NoiseFit

    @staticmethod
    def of(fit: NoiseFit) -> AccelFit:
        """The accelerometer coefficients of ``fit``, an IEEE-952 fit of an ADEV in micro-g."""
        q, n, b, k, r = (_scaled(c, ACCEL_PER_GYRO[name][1]) for name, c in fit.coefficients().items())
        return AccelFit(q, n, b, k, r, noise=fit)

    def coefficients(self) -> dict[str, Coefficient]:
        """Name (with unit) -> Coefficient, in the order of ACCEL_NAMES."""
        return {n: getattr(self, n) for n in ACCEL_NAMES}

    @property
    def confidence(self) -> float:
        return self.noise.confidence

    def model_adev_ug(self, tau_s) -> np.ndarray:
        """The fitted model's Allan deviation (micro-g) at ``tau_s`` (s)."""
        return self.noise.model_adev_dph(tau_s)


def fit_accel(result: AdevResult | DadevResult, confidence: float = CONFIDENCE) -> AccelFit:
    """``fit_noise`` of an accelerometer's Allan deviation in micro-g, as IEEE Std 1293 coefficients."""
    return AccelFit.of(fit_noise(result, confidence=confidence))
