"""Accelerometer noise coefficients (fogmon.davar.accel, fogmon.units): the IEEE Std 1293
terms from the IEEE-952 fit of an ADEV in micro-g, against hand-computed conversions and
simulated accelerometers of known noise."""
from __future__ import annotations

import math

import numpy as np
import pytest

import fogmon
from fogmon.davar.accel import AccelFit, fit_accel, to_ug
from fogmon.davar.theory import FLICKER_FACTOR
from fogmon.units import ACCEL_NAMES, ACCEL_PER_GYRO, G0_MPS2, coefficient_unit, g_per_unit

G0 = 9.80665


def test_the_units_table_names_the_ieee_1293_terms():
    assert ACCEL_NAMES == ("Q_mps", "VRW_mpsph", "Bias_ug", "AccRW_mpshsh", "Ramp_mpshh")
    assert [coefficient_unit(n) for n in ACCEL_NAMES] == ["m/s", "m/s/sqrt(h)", "ug", "m/s/h/sqrt(h)", "m/s/h^2"]
    assert g_per_unit("m/s^2") == g_per_unit("m/s²") == 1 / G0_MPS2 and g_per_unit(" mg ") == 1e-3
    assert g_per_unit("g") == 1.0 and g_per_unit("m/s") is None


@pytest.mark.parametrize("name, a_n, expected", [
    # sigma^2 = A_n tau^n of an acceleration in micro-g; each coefficient by hand (1 ug = 9.80665e-6 m/s^2)
    ("Q_mps", 3.0 * 4.0**2, 4.0 * G0 * 1e-6),                            # 3 Q^2 / tau^2: Q = 4 ug s
    ("VRW_mpsph", 100.0**2, 100.0 * G0 * 1e-6 * 60.0),                   # N^2 / tau: 100 ug/sqrt(Hz) x 60 sqrt(s/h)
    ("Bias_ug", FLICKER_FACTOR * 7.0**2, 7.0),                            # 0.664^2 B^2: B = 7 ug
    ("AccRW_mpshsh", 2.0**2 / 3.0, 2.0 * G0 * 1e-6 * 3600.0**1.5),        # K^2 tau / 3: 2 ug/sqrt(s) -> m/s/h/sqrt(h)
    ("Ramp_mpshh", 0.5**2 / 2.0, 0.5 * G0 * 1e-6 * 3600.0**2),            # R^2 tau^2 / 2: 0.5 ug/s -> m/s/h^2
])
def test_each_coefficient_is_the_hand_computed_conversion(name, a_n, expected):
    from fogmon.davar.fit import Coefficient, NoiseFit
    from fogmon.davar.theory import avar_terms_to_coefficients

    i = ACCEL_NAMES.index(name)
    a = np.zeros(5)
    a[i] = a_n
    gyro = avar_terms_to_coefficients(a)
    coefs = [Coefficient(float(v), float(v), float(v), True, float(v)) for v in gyro]
    fit = NoiseFit(*coefs, avar_terms=a, avar_se=np.zeros(5), avar_upper=np.zeros(5), confidence=0.683,
                   misfit=np.zeros(1, bool), worst_ratio=1.0)
    acc = AccelFit.of(fit)
    assert getattr(acc, name).value == pytest.approx(expected, rel=1e-12)
    assert list(ACCEL_PER_GYRO) == list(fit.coefficients())     # one factor per gyro term, in order


def test_a_simulated_accelerometer_gives_its_velocity_and_acceleration_random_walk():
    """White noise of 80 ug/sqrt(Hz) (VRW = 80e-6 x 9.80665 x 60 = 0.04707 m/s/sqrt(h)) and a
    random walk of 30 ug/sqrt(s) (AccRW = 30e-6 x 9.80665 x 216000 = 63.55 m/s/h/sqrt(h)),
    at 100 Hz over 4 h: both within their intervals' reach (3 sigma)."""
    fs, n = 100.0, 1_440_000
    rng = np.random.default_rng(11)
    g = 1.0 + 80e-6 * math.sqrt(fs) * rng.standard_normal(n) + np.cumsum(30e-6 / math.sqrt(fs) * rng.standard_normal(n))
    fit = fit_accel(fogmon.oadev(to_ug(g), fs))
    for name, true in (("VRW_mpsph", 80e-6 * G0 * 60), ("AccRW_mpshsh", 30e-6 * G0 * 216000)):
        c = getattr(fit, name)
        half = (c.hi - c.lo) / 2
        assert c.identifiable and abs(c.value - true) < 3 * half, (name, c, true)
    assert not fit.Ramp_mpshh.identifiable
    np.testing.assert_allclose(fit.model_adev_ug([1.0]), fit.noise.model_adev_dph([1.0]))
