"""Accelerometers read beside the gyros (aux channels accel_<axis>_g, g) from public files
as users have them: PX4 ULog's sensor_combined and sensor_accel, a ROS bag's
linear_acceleration, MDF4 channels the user names; each against the format's own library."""
from __future__ import annotations

import os

import numpy as np
import pytest

from fogmon.errors import FogmonError
from fogmon.sources.files.stamped import nearest_samples
from fogmon.sources.open import open_replay_source
from fogmon.sources.options import SourceOptions

PUBLIC = os.path.join(os.path.dirname(__file__), "..", "data", "public")
G0 = 9.80665


def pub(*parts: str) -> str:
    return os.path.join(PUBLIC, *parts)


def test_ulog_sensor_combined_accelerometer_matches_pyulog():
    import pyulog
    path = pub("ulog", "sample_bench_8s.ulg")
    rec = open_replay_source(path, SourceOptions()).to_recording()
    d = pyulog.ULog(path, ["sensor_combined"]).data_list[0].data
    for i, a in enumerate("xyz"):
        np.testing.assert_array_equal(rec.aux[f"accel_{a}_g"], d[f"accelerometer_m_s2[{i}]"].astype(np.float64) / G0)
    assert "accel_z_g" not in open_replay_source(path, SourceOptions(axis="z")).to_recording().aux   # one axis: none


def test_ulog_sensor_gyro_takes_sensor_accel_of_its_instance_nearest_in_time():
    import pyulog
    path = pub("ulog", "cubeorange_gyro_1hz.ulg")
    with pytest.warns(Warning):          # sensor_gyro:1 is decimated (1 Hz): read anyway, as asked
        rec = open_replay_source(path, SourceOptions(topic="sensor_gyro:1")).to_recording()
    acc = next(x for x in pyulog.ULog(path, ["sensor_accel"]).data_list if x.multi_id == 1).data
    gyro = next(x for x in pyulog.ULog(path, ["sensor_gyro"]).data_list if x.multi_id == 1).data
    want = nearest_samples(acc["timestamp_sample"] * 1.0, acc["x"].astype(np.float64) / G0,
                           gyro["timestamp_sample"] * 1.0)
    np.testing.assert_array_equal(rec.aux["accel_x_g"], want)
    assert np.isfinite(want).all()       # sampled together: each gyro sample has its accelerometer sample


def test_nearest_samples_within_half_a_period_else_nan():
    got = nearest_samples(np.array([0.0, 1.02, 2.6, 3.0]), np.array([1.0, 2.0, 3.0, 4.0]), np.array([0, 1, 2, 3.0]))
    np.testing.assert_array_equal(got, [1.0, 2.0, np.nan, 4.0])


def test_ros_bag_linear_acceleration_is_read_in_g():
    from pathlib import Path

    from rosbags.highlevel import AnyReader
    path = pub("ros1", "jackal_imu_50hz_20s.bag")
    rec = open_replay_source(path, SourceOptions()).to_recording()
    with AnyReader([Path(path)]) as r:
        conns = [c for c in r.connections if c.topic == "/imu/data"]
        z = np.array([r.deserialize(raw, c.msgtype).linear_acceleration.z for c, _, raw in r.messages(conns)])
    np.testing.assert_allclose(rec.aux["accel_z_g"], z / G0, rtol=1e-15)


def test_mdf4_accelerometer_channels_the_user_names():
    import asammdf
    path = pub("mdf", "canmod_imu_decoded_8s.mf4")
    src = open_replay_source(path, SourceOptions(channel="AngularRateZ",
                                                 accel_channels="AccelerationX,AccelerationY,z=AccelerationZ"))
    rec = src.to_recording()
    with asammdf.MDF(path) as mdf:
        for a in "xyz":
            sig = mdf.get(f"Acceleration{a.upper()}")
            assert sig.unit == "m/s^2"
            np.testing.assert_allclose(rec.aux[f"accel_{a}_g"], np.asarray(sig.samples, float) / G0, rtol=1e-15)
    with pytest.raises(FogmonError, match=r"accel_channels: no channel 'AccelX' in the file"):
        open_replay_source(path, SourceOptions(channel="AngularRateZ", accel_channels="AccelX"))
    with pytest.raises(FogmonError, match="unit 'deg/s' is not an acceleration unit"):
        open_replay_source(path, SourceOptions(channel="AngularRateZ", accel_channels="AngularRateX"))
