"""The accelerometers in the .rrd (fogmon.sinks.rerun.accel): each window's IEEE Std 1293
coefficients and log10 ADEV (micro-g) as the pipeline fitted them, a tab of their own
beside the gyros' layout, and no accelerometer entity for a stream without them."""
from __future__ import annotations

import numpy as np
import pytest
from helpers.doubles import ListSource
from helpers.rrd import read_scalars, read_views
from rerun.chunk import RrdReader

from fogmon.pipeline import PipelineConfig, run_pipeline
from fogmon.sinks.base import ACCEL_COEFFICIENTS, Sink
from fogmon.sinks.rerun.sink import RerunSink

AXES = ("x", "y", "z")
FS, N = 50.0, 12_000


class Keep(Sink):
    def __init__(self):
        self.accel = {}

    def accel_frames(self, d, fit, t_end, accel):
        self.accel.setdefault(accel, []).append((d, fit, t_end))


@pytest.fixture(scope="module")
def rrd(tmp_path_factory):
    rng = np.random.default_rng(2)
    t = np.arange(N) / FS
    rate = 60 * 0.05 * np.sqrt(FS) * rng.standard_normal((N, 3))
    aux = {f"accel_{a}_g": np.array([0, 0, 1.0])[j] + 100e-6 * np.sqrt(FS) * rng.standard_normal(N)
           for j, a in enumerate(AXES)}
    path = tmp_path_factory.mktemp("rrd") / "accel.rrd"
    keep = Keep()
    run_pipeline(ListSource(t, rate, [4000] * 3, FS, aux=aux, axes=AXES), PipelineConfig(window_s=40.96, hop_s=20.48),
                 [RerunSink(rrd_path=str(path)), keep])
    return str(path), keep


def test_each_window_of_each_accelerometer_is_in_the_rrd(rrd):
    path, keep = rrd
    for a in AXES:
        fits = keep.accel[a]
        t_end = np.concatenate([t for _, _, t in fits])
        ts, vals = read_scalars(path, f"/accel/{a}/coef/VRW_mpsph")
        np.testing.assert_allclose(ts, t_end, atol=1e-9)
        np.testing.assert_allclose(vals[:, 0], np.concatenate([f.VRW_mpsph.value for _, f, _ in fits]), rtol=1e-6)
        ts, vals = read_scalars(path, f"/accel/{a}/dadev/log10_adev_ug")
        np.testing.assert_allclose(vals, np.log10(np.concatenate([d.adev_dph for d, _, _ in fits])), rtol=1e-6)


def test_the_accelerometers_have_views_of_their_own(rrd):
    views = read_views(rrd[0])
    curve = views["Accelerometers, current window: ADEV (ug) vs tau (s), log-log"]
    assert curve["origin"] == "/accel" and "/accel/x/adev_curve/**" in curve["contents"]
    for n, u in ACCEL_COEFFICIENTS.items():
        v = views[f"{n} ({u}): x red, y green, z blue; \u25bc upper limit"]
        assert v["contents"] == [f"/accel/{a}/coef/{n}/**" for a in AXES]
    assert "N_dpsh (deg/sqrt(h)): x red, y green, z blue; \u25bc upper limit" in views   # the gyros' layout stays


def test_a_stream_without_accelerometers_draws_none(tmp_path):
    path = tmp_path / "gyro.rrd"
    rng = np.random.default_rng(3)
    run_pipeline(ListSource(np.arange(N) / FS, rng.standard_normal(N), [N], FS),
                 PipelineConfig(window_s=40.96, hop_s=20.48), [RerunSink(rrd_path=str(path))])
    entities = {str(ch.entity_path) for ch in RrdReader(str(path)).stream()}
    assert not any(e.startswith("/accel") for e in entities) and "/coef/N_dpsh" in entities
    assert not any("Accelerometer" in name for name in read_views(str(path)))
