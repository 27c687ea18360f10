"""Other tools' recordings written with the formats' own libraries (rosbags, asammdf,
lasio; a minimal ULog byte by byte per the ULog spec, pyulog has no writer), for the
reader tests and benchmarks/bench_readers.py. Each takes the stamps ``t`` (s), the rate
(deg/h) and the samples to ``keep``."""
from __future__ import annotations

import math
import struct

import numpy as np

DPH_PER_RPS = 3600 * 180 / math.pi


def write_imu_bag(path, t, rate_dph, keep, kind, topic="/imu/data", t0_ns=1_732_600_000_000_000_000):
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)  # ROS 1 Header has seq
    T = ts.types
    if kind == "ros1":
        w = Writer1(path)
    else:
        w = Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3)
    with w:
        conn = w.add_connection(topic, "sensor_msgs/msg/Imu", typestore=ts)
        other = w.add_connection("/temp", "std_msgs/msg/Float64", typestore=ts)
        w.write(other, t0_ns, (ts.serialize_ros1 if kind == "ros1" else ts.serialize_cdr)(
            T["std_msgs/msg/Float64"](data=21.0), "std_msgs/msg/Float64"))
        for i in np.flatnonzero(keep):
            ns = t0_ns + int(round(t[i] * 1e9))
            stamp = T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
            w_rps = rate_dph[i] / DPH_PER_RPS
            msg = T["sensor_msgs/msg/Imu"](
                header=T["std_msgs/msg/Header"](seq=int(i), stamp=stamp, frame_id="imu") if kind == "ros1" else
                T["std_msgs/msg/Header"](stamp=stamp, frame_id="imu"),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=T["geometry_msgs/msg/Vector3"](x=0.5 * w_rps, y=-w_rps, z=w_rps),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=np.zeros(9))
            data = ts.serialize_ros1(msg, "sensor_msgs/msg/Imu") if kind == "ros1" else \
                ts.serialize_cdr(msg, "sensor_msgs/msg/Imu")
            w.write(conn, ns + 3_000_000, data)   # received 3 ms after the stamp: the stamp is the time base

def write_ulog(path, t, rate_dph, keep, temp_c=35.0):
    """A minimal ULog (spec: docs.px4.io ULog file format): header, flag bits, format and
    subscription of sensor_gyro, one data message per sample (timestamps in us, x/y/z rad/s:
    0.5, -1 and 1 times the rate)."""
    def msg(kind, payload):
        return struct.pack("<HB", len(payload), ord(kind)) + payload

    out = bytearray(b"ULog\x01\x12\x35" + b"\x01" + struct.pack("<Q", 0))
    out += msg("B", bytes(8) + bytes(8) + bytes(24))
    fmt = b"sensor_gyro:uint64_t timestamp;uint64_t timestamp_sample;float x;float y;float z;float temperature;"
    out += msg("F", fmt)
    out += msg("A", struct.pack("<BH", 0, 1) + b"sensor_gyro")
    for i in np.flatnonzero(keep):
        us = int(round(1e6 * (10.0 + t[i])))
        w = rate_dph[i] / DPH_PER_RPS
        out += msg("D", struct.pack("<HQQffff", 1, us + 250, us, 0.5 * w, -w, w, temp_c))
    path.write_bytes(bytes(out))

def write_mdf(path, t, rate, keep, unit="deg/s", name="GyroZ"):
    from asammdf import MDF, Signal
    mdf = MDF(version="4.10")
    mdf.append([Signal(samples=rate[keep] / 3600.0 if unit == "deg/s" else rate[keep], timestamps=10.0 + t[keep],
                       name=name, unit=unit),
                Signal(samples=np.full(keep.sum(), 40.0), timestamps=10.0 + t[keep], name="Temp", unit="degC")])
    mdf.save(path, overwrite=True)
    mdf.close()

def write_las(path, t, rate, keep, depth_index=False, unit="DEG/HR"):
    import lasio
    las = lasio.LASFile()
    tt, rr = t[keep], rate[keep]
    if depth_index:
        las.append_curve("DEPT", 1000.0 + 0.01 * np.arange(len(tt)), unit="M")
    las.append_curve("TIME", 1000.0 * tt, unit="MS")
    las.append_curve("GYRO", rr, unit=unit)
    las.append_curve("TEMP", np.full(len(tt), 80.0), unit="DEGC")
    las.write(str(path), version=2.0)
