"""The model check (fogmon.davar.adequacy): the fitted model against the measured ADEV."""
import dataclasses

import numpy as np
import pytest

from fogmon.davar.adequacy import check_model
from fogmon.davar.record import whole_record_fit
from fogmon.sim.model import Noise, SensorModel
from fogmon.sim.simulate import simulate


@pytest.mark.parametrize("seed", [5, 13, 30])
def test_a_deterministic_ramp_is_checked_against_the_model_its_edf_describes(seed):
    # exact records of N 0.01 deg/sqrt(h), B 0.02 deg/h, R 20 deg/h^2 at 10 Hz over 2 h: the ADEV
    # takes the ramp as deterministic (EDF ~1e5-1e6 at the longest taus); the five-term fit's
    # chance K weighted those taus as if their EDF were ~1000, and the check of that model warned
    # (these seeds: 0.4-1.0 % off at 102-1638 s, p 2e-4 to 5e-12)
    rec = simulate(SensorModel(10.0, noise=Noise(0.0, 0.01, 0.02, 0.0, 20.0)), duration_s=7200.0, seed=seed)
    adev, fit = whole_record_fit(rec.rate_dph, None, 10.0)
    assert np.isfinite(adev.ramp_k) and fit.check_terms is not None
    assert check_model(adev, dataclasses.replace(fit, check_terms=None)).departs  # the model the fit prints
    check = check_model(adev, fit)
    assert not check.departs
    assert check.worst_ratio < 1.05


def test_without_a_deterministic_ramp_the_fitted_model_is_checked():
    rec = simulate(SensorModel(10.0, noise=Noise(0.0, 0.01, 0.02, 0.0, 0.0)), duration_s=3600.0, seed=1)
    adev, fit = whole_record_fit(rec.rate_dph, None, 10.0)
    assert np.isnan(adev.ramp_k) and fit.check_terms is None
    np.testing.assert_array_equal(fit.check_adev_dph(adev.tau_s), fit.model_adev_dph(adev.tau_s))
