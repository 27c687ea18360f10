"""ROS 1 bags, ROS 2 bags (a folder with metadata.yaml, sqlite3 or MCAP storage) and MCAP
files with sensor_msgs/Imu messages, read with ``rosbags`` (``fogmon[ros]``).

One topic (``topic``, default the only Imu topic); ``angular_velocity`` (rad/s ->
deg/h) of the axes ``axis`` asks (fogmon.sources.files.stamped.imu_axes): without it all
three, a multi-axis source with ``linear_acceleration`` as aux channels ``accel_<axis>_g``
(m/s^2 -> g); with one axis a one-axis source of that gyro alone. Time base:
``header.stamp`` of each message (s), on fogmon's grid as fogmon.sources.files.stamped
describes (missing messages become counted invalid placeholders); time 0 is the first
message's stamp, whose Unix time is kept in the metadata (``t0_unix_s``).

A ROS 2 bag or MCAP file with a channel whose schema rosbags cannot parse (a service
event type, a custom message) is read with rosbags' storage reader and its built-in
types instead: the Imu topic is read, the channels of unknown types are skipped and
counted (``channels_skipped``)."""
from __future__ import annotations

import contextlib
import os
import struct
from pathlib import Path

import numpy as np

from fogmon.errors import FogmonError
from fogmon.sources.files.listing import Entry, point_to_info, reading, stamped_entry
from fogmon.sources.files.stamped import DPH_PER_RPS, IMU_AXES, StampedSource, imu_axes
from fogmon.sources.options import SourceOptions
from fogmon.units import G0_MPS2

IMU_TYPE = "sensor_msgs/msg/Imu"


class _Rosbag2:
    """rosbags' ROS 2 storage reader (MCAP, sqlite3) with the reader interface fogmon uses
    (``connections``, ``messages``, ``deserialize``, ``is2``), deserializing with the
    built-in ROS 2 types only: for a file one of whose schemas rosbags cannot parse."""

    is2 = True

    def __init__(self, path: str, typestore) -> None:
        from rosbags.rosbag2 import Reader
        self._reader = Reader(Path(path))
        self._types = typestore
        self._reader.open()
        self.connections = self._reader.connections
        #: connections of a type the built-in types do not hold (not readable here)
        self.unknown = [c for c in self.connections if c.msgtype not in typestore.fielddefs]

    def messages(self, connections=()):
        return self._reader.messages(connections=connections)

    def deserialize(self, raw: bytes, msgtype: str):
        return self._types.deserialize_cdr(raw, msgtype)

    def close(self) -> None:
        self._reader.close()


def _open(path: str):
    """The opened reader of bag or MCAP ``path``: rosbags' AnyReader, or, for a ROS 2 file
    whose schemas it cannot all parse, ``_Rosbag2``; a one-line FogmonError naming the
    file when neither reads it."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_HUMBLE)
    try:
        with reading(f"{path}: not a readable ROS bag or MCAP file"):   # rosbags' own error types, and others
            reader = AnyReader([Path(path)], default_typestore=store)
            reader.open()
        return reader
    except FogmonError as e:
        first = e
    try:
        with reading(""):
            return _Rosbag2(path, store)
    except FogmonError:    # not a ROS 2 storage either: the first error says why
        pass
    raise first


def _topics(reader) -> list[str]:
    """Every topic of the file with its type and message count, for messages."""
    return [f"{c.topic} ({c.msgtype}, {c.msgcount})" for c in sorted(reader.connections, key=lambda c: c.topic)]


_STAMP_ROS1 = struct.Struct("<II")   # header.stamp sec, nsec after the uint32 seq
_STAMP_CDR = struct.Struct("<iI")    # sec, nanosec after the 4-byte CDR encapsulation header
#: angular_velocity x, y, z (rad/s), its covariance (9 float64, skipped), linear_acceleration x, y, z (m/s^2)
_VECTORS = struct.Struct("<3d72x3d")


def _vectors(msg) -> tuple[float, ...]:
    """angular_velocity x, y, z (rad/s) and linear_acceleration x, y, z (m/s^2) of a
    deserialized Imu message."""
    w, a = msg.angular_velocity, msg.linear_acceleration
    return w.x, w.y, w.z, a.x, a.y, a.z


def _verified_layout(raw: bytes, ros2: bool, msg) -> tuple | None:
    """(stamp struct, stamp offset, byte offset of angular_velocity) of a serialized Imu
    message, so that messages of the same length are read with two ``unpack_from`` calls
    instead of a full deserialization (several times faster). The layout is
    sensor_msgs/Imu's: header (ROS 1: seq, when the bag's Header has it; stamp; frame_id,
    the only variable-length field), orientation (4 float64), its covariance (9),
    angular_velocity (3), its covariance (9), linear_acceleration (3), its covariance (9).
    None (every such message is deserialized) unless the offsets reproduce ``msg``, the
    same message deserialized by rosbags, exactly (little-endian CDR only)."""
    if ros2:
        if len(raw) < 16 or raw[1] != 1:                      # big-endian CDR: not handled here
            return None
        (n,) = struct.unpack_from("<I", raw, 12)
        first = 4 + (16 + n - 4 + 7) // 8 * 8                 # float64 aligned to 8 from the CDR body
        candidates = [(_STAMP_CDR, 4, first)]
    else:                                                     # with a seq field (ROS 1 Header) or without
        candidates = []
        for at in (4, 0):
            if len(raw) >= at + 12:
                (n,) = struct.unpack_from("<I", raw, at + 8)
                candidates.append((_STAMP_ROS1, at, at + 12 + n))
    for stamp, at, first in candidates:
        off = first + 8 * (4 + 9)
        if len(raw) != first + 8 * (4 + 9 + 3 + 9 + 3 + 9):
            continue
        if stamp.unpack_from(raw, at) == (msg.header.stamp.sec, msg.header.stamp.nanosec) and \
                _VECTORS.unpack_from(raw, off) == _vectors(msg):
            return stamp, at, off
    return None


def open_source(path: str, opts: SourceOptions) -> StampedSource:
    """The Imu topic ``opts.topic``, axes ``opts.axis`` (``imu_axes``) of the
    bag or MCAP file ``path`` as a StampedSource; a missing topic or a topic of another
    type is a one-line FogmonError naming the file and the Imu topics it has."""
    axes = imu_axes(opts.axis, path)
    reader = _open(path)
    skipped = len(getattr(reader, "unknown", ()))
    try:
        topic, conns = _topic(path, reader, opts.topic)
        with reading(f"{path}: topic {topic}: unreadable message"):   # a corrupt message or chunk
            ns, v = _read_messages(reader, conns)
    finally:
        with contextlib.suppress(FogmonError), reading(""):
            reader.close()
    where = f"{path} topic {topic}"
    if len(ns) and not np.any(ns):
        raise FogmonError(f"{where}: field header.stamp: zero in every message (the driver does not stamp them)")
    t0 = int(ns[0]) if len(ns) else 0
    cols = [IMU_AXES.index(a) for a in axes]
    field = f"angular_velocity.{','.join(axes)}"
    several = len(axes) > 1
    accel = {f"accel_{a}_g": v[:, 3 + c] / G0_MPS2 for a, c in zip(axes, cols, strict=True)} if several else None
    src = StampedSource((ns - t0) * 1e-9, v[:, cols if several else cols[0]] * DPH_PER_RPS, accel,
                        name=f"ROS {os.path.basename(path)} {topic} {field}", where=where, time_field="header.stamp",
                        meta={"sensor": f"{topic} {field}", "t0_unix_s": repr(t0 * 1e-9)},
                        max_abs_dph=opts.file_gate_dph, axes=axes if several else (),
                        counters={"channels_skipped": skipped} if skipped else None, nominal_hz=opts.sample_rate_hz,
                        force_rate=opts.force_rate, resample_hz=opts.resample_hz)
    src.ros_topic = topic  # the topic a Kalibr export names
    return src


def _topic(path: str, reader, topic: str | None) -> tuple[str, list]:
    """The Imu topic to read (``topic``, or the file's only Imu topic) and its connections;
    a one-line FogmonError naming the file's Imu topics when there is no such topic."""
    imu = sorted({c.topic for c in reader.connections if c.msgtype == IMU_TYPE})
    have = point_to_info(path, "topics", _topics(reader))
    if topic is None:
        if len(imu) != 1:
            raise FogmonError(f"{path}: {'no' if not imu else len(imu)} {IMU_TYPE} topics"
                              f"{(': ' + ', '.join(imu)) if imu else ''}; name one with `topic` (the file has: "
                              f"{have})")
        topic = imu[0]
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        raise FogmonError(f"{path}: `topic`: no topic {topic!r} in the file (it has: {have})")
    other = {c.msgtype for c in conns} - {IMU_TYPE}
    if other:
        raise FogmonError(f"{path}: `topic`: {topic!r} carries {', '.join(sorted(other))}, not {IMU_TYPE} (the "
                          f"file has: {have})")
    return topic, conns


def info(path: str, opts: SourceOptions) -> list[Entry]:
    """One Entry per topic of the bag or MCAP file ``path``: its type, message count and
    the rate and span of the times the recorder received the messages."""
    reader = _open(path)
    out = []
    try:
        with reading(f"{path}: unreadable messages"):   # a corrupt chunk
            for c in sorted(reader.connections, key=lambda c: c.topic):
                t = [ts * 1e-9 for _, ts, _ in reader.messages(connections=[c])]
                unit = "rad/s, m/s^2" if c.msgtype == IMU_TYPE else ""
                out.append(stamped_entry(c.topic, c.msgtype, t, unit))
    finally:
        with contextlib.suppress(FogmonError), reading(""):
            reader.close()
    return out


def _read_messages(reader, conns: list) -> tuple[np.ndarray, np.ndarray]:
    """Header stamps (integer ns, exact) and (angular_velocity x, y, z in rad/s,
    linear_acceleration x, y, z in m/s^2) of every message of ``conns``, read from the
    raw bytes at offsets verified once per message length."""
    n = sum(c.msgcount for c in conns)
    ns = np.empty(n, np.int64)
    v = np.empty((n, 6))
    i = 0
    layouts: dict[int, tuple | None] = {}   # message length -> verified field offsets
    for conn, _, raw in reader.messages(connections=conns):
        if len(raw) not in layouts:
            layouts[len(raw)] = _verified_layout(raw, reader.is2, reader.deserialize(raw, conn.msgtype))
        lay = layouts[len(raw)]
        if lay is None:
            msg = reader.deserialize(raw, conn.msgtype)
            ns[i] = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            v[i] = _vectors(msg)
        else:
            sec, nsec = lay[0].unpack_from(raw, lay[1])
            ns[i] = sec * 1_000_000_000 + nsec
            v[i] = _VECTORS.unpack_from(raw, lay[2])
        i += 1
    return ns[:i], v[:i]
