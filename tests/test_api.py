"""fogmon.oadev / fogmon.dadev keep platform motion out as `fogmon replay` does."""
import numpy as np
import pytest

import fogmon
from fogmon.davar import batch
from fogmon.errors import FogmonWarning
from fogmon.motion_gate import gate_record
from fogmon.sim.model import Noise, SensorModel
from fogmon.sim.simulate import simulate

FS = 100.0


@pytest.fixture(scope="module")
def turned():
    rec = simulate(SensorModel(FS, 12.0, Noise(N_dpsh=0.05, B_dph=0.2)), duration_s=900.0, seed=2)
    r = rec.rate_dph.copy()
    r[(rec.t_s >= 2.0) & (rec.t_s < 5.0)] += 3600.0 * 30.0        # a turn at 30 deg/s from 2 s
    return r


def test_motion_is_kept_out_by_default_and_said(turned):
    with pytest.warns(FogmonWarning, match=r"platform motion: 1 span\(s\) \(1\.\d+\.\.5\.\d+ s"):
        res = fogmon.oadev(turned, FS)
    gated = gate_record(turned, FS)
    assert not gated.valid[200:500].any() and gated.samples_excluded < 400
    np.testing.assert_array_equal(res.adev_dph, batch.oadev(turned, FS, valid=gated.valid).adev_dph)
    np.testing.assert_array_equal(fogmon.oadev(turned, FS, exclude_motion=False).adev_dph,
                                  batch.oadev(turned, FS).adev_dph)
    with pytest.warns(FogmonWarning):
        surf = fogmon.dadev(turned, FS, window_s=300.0, hop_s=150.0)
    np.testing.assert_array_equal(surf.adev_dph, batch.dadev(turned, FS, 300.0, 150.0, valid=gated.valid).adev_dph)


def test_a_record_at_rest_is_analysed_whole(recwarn):
    rec = simulate(SensorModel(FS, 12.0, Noise(N_dpsh=0.05)), duration_s=300.0, seed=4)
    np.testing.assert_array_equal(fogmon.oadev(rec.rate_dph, FS).adev_dph, batch.oadev(rec.rate_dph, FS).adev_dph)
    assert not [w for w in recwarn if issubclass(w.category, FogmonWarning)]
