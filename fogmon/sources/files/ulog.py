"""PX4 ULog flight logs, read with ``pyulog`` (``fogmon[ulog]``).

Topic (``topic``): by default the gyro topic with the most samples among
``sensor_combined`` (gyro_rad[0..2] in rad/s) and ``sensor_gyro`` (fields x, y, z in
rad/s, temperature in deg C), any instance: real logs lack ``sensor_gyro`` or log it
decimated (1 Hz) beside a 250 Hz ``sensor_combined``. ``NAME`` or ``NAME:INSTANCE`` picks
one; a topic with under DECIMATED of the samples of the fullest gyro topic is read with a
warning. Axes ``axis`` (fogmon.sources.files.stamped.imu_axes: without it all three, a
multi-axis source; one axis, a one-axis source). Time base: the topic's
``timestamp_sample`` (us since boot) where it has one, else ``timestamp``, on fogmon's
grid as fogmon.sources.files.timing describes; times stay in s since boot.

Read with several axes, the accelerometer of the same axes becomes the aux channels
``accel_<axis>_g`` (g: m/s^2 / 9.80665): ``sensor_combined``'s ``accelerometer_m_s2[0..2]``
(NaN where its ``accelerometer_timestamp_relative`` marks it invalid), for
``sensor_gyro`` the ``sensor_accel`` of the same instance, each gyro sample paired with
the accelerometer sample nearest in ``timestamp_sample`` within half a gyro period
(else NaN)."""
from __future__ import annotations

import os
import warnings

import numpy as np

from fogmon.errors import FogmonError, FogmonWarning
from fogmon.sources.files.listing import Entry, bounded, reading, stamped_entry
from fogmon.sources.files.stamped import DPH_PER_RPS, StampedSource, imu_axes, nearest_samples
from fogmon.sources.options import SourceOptions
from fogmon.units import G0_MPS2

#: topic -> field of each axis (rad/s)
AXIS_FIELDS = {"sensor_gyro": {"x": "x", "y": "y", "z": "z"},
               "sensor_combined": {"x": "gyro_rad[0]", "y": "gyro_rad[1]", "z": "gyro_rad[2]"}}
#: a gyro topic with fewer than this fraction of the samples of the fullest one is decimated
DECIMATED = 0.25
#: gyro topic -> (the accelerometer's topic, field of each axis, m/s^2)
ACCEL_FIELDS = {"sensor_combined": ("sensor_combined", {a: f"accelerometer_m_s2[{i}]" for i, a in enumerate("xyz")}),
                "sensor_gyro": ("sensor_accel", {"x": "x", "y": "y", "z": "z"})}
#: accelerometer_timestamp_relative of an invalid accelerometer sample (PX4 RELATIVE_TIMESTAMP_INVALID)
RELATIVE_TIMESTAMP_INVALID = 2147483647


def _read(path: str, topics: list[str] | None):
    """The ULog ``path`` read by pyulog (only ``topics``; None: all), or a one-line
    FogmonError naming the file."""
    import pyulog
    with reading(f"{path}: not a readable ULog file"), bounded(path) as fh:   # pyulog: plain exceptions
        return pyulog.ULog(fh, topics)
    raise AssertionError("unreachable")


def _time_field(d: dict) -> str:
    return "timestamp_sample" if "timestamp_sample" in d else "timestamp"


def _label(data) -> str:
    return f"{data.name}:{data.multi_id}"


def _pick(path: str, log, topic: str | None):
    """The logged data of ``topic`` (NAME or NAME:INSTANCE; None: the gyro topic with the
    most samples) and a warning text when it is decimated (else None)."""
    found = [d for d in log.data_list if d.name in AXIS_FIELDS and len(d.data.get("timestamp", ())) > 0]
    have = ", ".join(f"{_label(d)} ({len(d.data['timestamp'])} samples)" for d in found) or "none"
    if topic is None:
        if not found:
            raise FogmonError(f"{path}: no gyro topic ({', '.join(AXIS_FIELDS)}) in the log; fogmon info {path} "
                              f"lists its topics")
        data = max(found, key=lambda d: (len(d.data["timestamp"]), d.name == "sensor_combined"))
    else:
        name, _, inst = topic.partition(":")
        if name not in AXIS_FIELDS:
            raise FogmonError(f"{path}: `topic` {name!r} is not a gyro topic fogmon reads "
                              f"({', '.join(AXIS_FIELDS)}; the log has: {have})")
        if inst and not inst.isdigit():
            raise FogmonError(f"{path}: `topic` instance {inst!r} of {topic!r} is not a whole number")
        data = next((d for d in found if d.name == name and d.multi_id == int(inst or 0)), None)
        if data is None:
            raise FogmonError(f"{path}: `topic`: no {topic!r} in the log (gyro topics: {have})")
    most = max(found, key=lambda d: len(d.data["timestamp"]))
    n, n_most = len(data.data["timestamp"]), len(most.data["timestamp"])
    warn = None
    if n < DECIMATED * n_most:
        e, e_most = _entry(data), _entry(most)
        warn = (f"{path}: topic {_label(data)} holds {n} samples at {e.rate_hz:.4g} Hz, {_label(most)} {n_most} at "
                f"{e_most.rate_hz:.4g} Hz: {_label(data)} is decimated (its Allan deviation starts at "
                f"{1 / e.rate_hz:.3g} s)")
    return data, warn


def _entry(data) -> Entry:
    d = data.data
    fields = [f for f in d if f not in ("timestamp", "timestamp_sample")]
    unit = "rad/s" if data.name in AXIS_FIELDS else ""
    return stamped_entry(_label(data), f"topic ({len(fields)} fields)", np.asarray(d[_time_field(d)]) * 1e-6, unit)


def info(path: str, opts: SourceOptions) -> list[Entry]:
    """One Entry per topic instance of the ULog ``path`` (rate and span from its
    ``timestamp_sample`` or ``timestamp``)."""
    return [_entry(d) for d in sorted(_read(path, None).data_list, key=_label)]


def open_source(path: str, opts: SourceOptions) -> StampedSource:
    """Topic ``opts.topic`` (see the module docstring), axes ``opts.axis``
    (``imu_axes``) of the ULog ``path`` as a StampedSource (temperature as aux
    ``temp_c`` where logged)."""
    axes = imu_axes(opts.axis, path)
    log = _read(path, [*AXIS_FIELDS, "sensor_accel"])
    data, warn = _pick(path, log, opts.topic)
    if warn:
        warnings.warn(warn, FogmonWarning, stacklevel=2)
    name, label, d = data.name, _label(data), data.data
    fields = [AXIS_FIELDS[name][a] for a in axes]
    for field in fields:
        if field not in d:
            raise FogmonError(f"{path}: topic {label}: no field {field} in the log")
    time_field = _time_field(d)
    aux = {"temp_c": d["temperature"]} if "temperature" in d else {}
    several = len(axes) > 1
    if several:
        aux.update(_accelerometers(log, data, axes, np.asarray(d[time_field], dtype=np.float64)))
    rate = np.column_stack([d[f] for f in fields]) if several else d[fields[0]]
    what = f"{label} {','.join(fields)}"
    chosen = "" if opts.topic else " (the gyro topic with the most samples)"
    return StampedSource(np.asarray(d[time_field], dtype=np.float64) * 1e-6,
                         np.asarray(rate, dtype=np.float64) * DPH_PER_RPS, aux or None,
                         name=f"PX4 ULog {os.path.basename(path)} {what}{chosen}", where=f"{path} topic {label}",
                         time_field=time_field, meta={"sensor": what}, max_abs_dph=opts.file_gate_dph,
                         axes=axes if several else (), nominal_hz=opts.sample_rate_hz, force_rate=opts.force_rate,
                         resample_hz=opts.resample_hz)


def _accelerometers(log, data, axes: tuple[str, ...], t_us: np.ndarray) -> dict[str, np.ndarray]:
    """The accelerometer of ``axes`` at the gyro samples of ``data`` (times ``t_us``) as
    aux channels accel_<axis>_g (g; see the module docstring); none when the log has none."""
    topic, fields = ACCEL_FIELDS[data.name]
    if topic == data.name:
        d = data.data
        if not all(fields[a] in d for a in axes):
            return {}
        bad = np.asarray(d.get("accelerometer_timestamp_relative", np.zeros(len(t_us)))) == RELATIVE_TIMESTAMP_INVALID
        return {f"accel_{a}_g": np.where(bad, np.nan, np.asarray(d[fields[a]], dtype=np.float64) / G0_MPS2)
                for a in axes}
    acc = next((x for x in log.data_list if x.name == topic and x.multi_id == data.multi_id), None)
    if acc is None or not all(fields[a] in acc.data for a in axes):
        return {}
    ta = np.asarray(acc.data[_time_field(acc.data)], dtype=np.float64)
    return {f"accel_{a}_g": nearest_samples(ta, np.asarray(acc.data[fields[a]], dtype=np.float64) / G0_MPS2, t_us)
            for a in axes}
