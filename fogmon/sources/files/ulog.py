"""PX4 ULog flight logs, read with ``pyulog`` (``fogmon[ulog]``).

Topic (``topic``): ``sensor_gyro`` (default; fields x, y, z in rad/s and temperature in
deg C; ``sensor_gyro:1`` for the second instance) or ``sensor_combined`` (gyro_rad[0..2]
in rad/s). Axes ``axis`` (fogmon.sources.files.stamped.imu_axes: without it all three, a
multi-axis source; one axis, a one-axis source). Time base: the topic's
``timestamp_sample`` (us since boot) where it has one, else ``timestamp``, on fogmon's
grid as fogmon.sources.files.stamped describes; times stay in s since boot."""
from __future__ import annotations

import os

import numpy as np

from fogmon.errors import FogmonError
from fogmon.sources.files.stamped import DPH_PER_RPS, StampedSource, imu_axes
from fogmon.sources.options import SourceOptions

#: topic -> field of each axis (rad/s)
AXIS_FIELDS = {"sensor_gyro": {"x": "x", "y": "y", "z": "z"},
               "sensor_combined": {"x": "gyro_rad[0]", "y": "gyro_rad[1]", "z": "gyro_rad[2]"}}


def open_source(path: str, opts: SourceOptions) -> StampedSource:
    """Topic ``opts.topic`` (NAME or NAME:INSTANCE), axes ``opts.axis``
    (``imu_axes``) of the ULog ``path`` as a StampedSource (temperature as aux ``temp_c``
    where logged)."""
    topic = opts.topic or "sensor_gyro"
    axes = imu_axes(opts.axis, path)
    data = _topic_data(path, topic)
    name = data.name
    d = data.data
    fields = [AXIS_FIELDS[name][a] for a in axes]
    for field in fields:
        if field not in d:
            raise FogmonError(f"{path}: topic {topic}: no field {field} in the log")
    time_field = "timestamp_sample" if "timestamp_sample" in d else "timestamp"
    aux = {"temp_c": d["temperature"]} if "temperature" in d else None
    where = f"{path} topic {name}:{data.multi_id}"
    several = len(axes) > 1
    rate = np.column_stack([d[f] for f in fields]) if several else d[fields[0]]
    what = f"{name}:{data.multi_id} {','.join(fields)}"
    return StampedSource(np.asarray(d[time_field], dtype=np.float64) * 1e-6,
                         np.asarray(rate, dtype=np.float64) * DPH_PER_RPS, aux,
                         name=f"PX4 ULog {os.path.basename(path)} {what}", where=where, time_field=time_field,
                         meta={"sensor": what}, max_abs_dph=opts.file_gate_dph, axes=axes if several else ())


def _topic_data(path: str, topic: str):
    """The logged data of ``topic`` (NAME or NAME:INSTANCE) in the ULog ``path``; a
    one-line FogmonError for a topic fogmon does not read, a broken file or a missing
    instance (naming the instances the log has)."""
    import pyulog

    name, _, inst = topic.partition(":")
    if name not in AXIS_FIELDS:
        raise FogmonError(f"{path}: field topic: {name!r} is not a gyro topic fogmon reads ({', '.join(AXIS_FIELDS)})")
    if inst and not inst.isdigit():
        raise FogmonError(f"{path}: field topic: instance {inst!r} of {topic!r} is not a whole number")
    try:
        log = pyulog.ULog(path, [name])
    except Exception as e:  # pyulog raises plain exceptions for broken files
        why = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise FogmonError(f"{path}: not a readable ULog file ({why})") from None
    found = [d for d in log.data_list if d.name == name]
    data = next((d for d in found if d.multi_id == int(inst or 0)), None)
    if data is None:
        have = ", ".join(f"{d.name}:{d.multi_id}" for d in found) or "none"
        raise FogmonError(f"{path}: field topic: no {topic!r} in the log (instances of {name}: {have})")
    return data
