"""ASAM MDF4 measurement files, read with ``asammdf`` (``fogmon[mdf]``).

``channel`` NAME: a rate channel, its unit from the file (deg/h, deg/s, rad/s, ...;
``rate_unit`` when the file has none), its own time stamps (s) on fogmon's grid as
fogmon.sources.files.timing describes. ``accel_channels``: accelerometer channels (unit
from the file: fogmon.units.G_PER_UNIT), each as the aux channel ``accel_<axis>_g`` in g,
paired with the rate samples nearest in time (fogmon.sources.files.stamped.nearest_samples).
Raw CAN frames in the MDF bus-logging format are a
CAN log instead: give ``dbc`` (fogmon.sources.files.can_log, through python-can's MF4
reader)."""
from __future__ import annotations

import os

import numpy as np

from fogmon.block import is_axis_name
from fogmon.errors import FogmonError
from fogmon.sources.files.listing import Entry, point_to_info, reading, stamped_entry
from fogmon.sources.files.stamped import StampedSource, dph_per_unit, nearest_samples
from fogmon.sources.options import SourceOptions
from fogmon.units import G_PER_UNIT, g_per_unit

#: channel types (MDF4 cn_type) whose bytes lie in the data record: fixed length, master, sync
IN_RECORD = (0, 2, 4)
#: names of the master (time) channel, not listed as data
MASTER_NAMES = ("t", "time")


def _read(path: str):
    import asammdf
    with reading(f"{path}: not a readable MDF file"):   # asammdf raises MdfException and plain errors
        mdf = asammdf.MDF(path)
    try:
        _check_layout(mdf, path)
    except FogmonError:
        mdf.close()
        raise
    return mdf


def check_layout(path: str) -> None:
    """FogmonError unless the MDF file ``path`` opens and its channels lie inside their
    records, checked without decoding its bus logging: asammdf decodes an MF4 CAN log
    while it opens it (python-can's MF4 reader), where a corrupt channel crashes it."""
    import asammdf
    with reading(f"{path}: not a readable MDF file"):
        mdf = asammdf.MDF(path, process_bus_logging=False)  # type: ignore[call-arg]  # an MDF4 option (mdf_v4.py)
    with mdf:
        _check_layout(mdf, path)


def _check_layout(mdf, path: str) -> None:
    """FogmonError unless every channel lies inside its data group's record: asammdf's
    C extension reads a channel whose byte offset a corrupt file puts beyond the record
    out of bounds (a crash, not an exception)."""
    for g, group in enumerate(getattr(mdf, "groups", ())):
        cg = group.channel_group
        record = int(cg.samples_byte_nr) + int(getattr(cg, "invalidation_bytes_nr", 0))
        held = sum(int(b.original_size) for b in getattr(group, "data_blocks", ()))
        if held and record > held:   # asammdf would allocate buffers of the record size (GB from a flipped bit)
            raise FogmonError(f"{path}: not a readable MDF file (corrupt: data group {g} has {record}-byte records "
                              f"but its data blocks hold {held} bytes)")
        for ch in group.channels:
            end = int(ch.byte_offset) + (int(ch.bit_offset) + int(ch.bit_count) + 7) // 8
            if getattr(ch, "channel_type", 0) in IN_RECORD and end > record:
                raise FogmonError(f"{path}: not a readable MDF file (corrupt: channel {ch.name!r} of data group "
                                  f"{g} ends at byte {end} of a {record}-byte record)")


def info(path: str, opts: SourceOptions) -> list[Entry]:
    """One Entry per channel of the MDF file ``path`` (data group and channel index in
    the type; rate and span from the group's master time)."""
    mdf = _read(path)
    out = []
    with reading(f"{path}: unreadable MDF channel"), mdf:
        if True:
            for name, where in sorted(mdf.channels_db.items()):
                if name in MASTER_NAMES:
                    continue
                for group, index in where:
                    ch = mdf.groups[group].channels[index]
                    t = mdf.get_master(group)
                    out.append(stamped_entry(name, f"channel {group}/{index}", t, getattr(ch, "unit", "") or ""))
    return out


def open_source(path: str, opts: SourceOptions) -> StampedSource:
    """Channel ``opts.channel`` of the MDF file ``path`` as a StampedSource; a
    missing channel is a one-line FogmonError naming the file and listing channels."""
    mdf = _read(path)
    with mdf:
        names = sorted(n for n in mdf.channels_db if n not in MASTER_NAMES)
        channel = opts.channel
        if not channel:
            raise FogmonError(f"{path}: an MDF4 file needs `channel` NAME (the rate channel; the file has "
                              f"{point_to_info(path, 'channels', names)}) or `dbc` F for raw CAN frames")
        if channel not in mdf.channels_db:
            raise FogmonError(f"{path}: `channel`: no channel {channel!r} in the file (it has: "
                              f"{point_to_info(path, 'channels', names)})")
        with reading(f"{path}: `channel` {channel!r}"):   # several groups hold the name, or undecodable
            sig = mdf.get(channel)
            values, stamps = np.asarray(sig.samples, dtype=np.float64), np.asarray(sig.timestamps, np.float64)
            invalid = getattr(sig, "invalidation_bits", None)   # samples the logger marked invalid
            invalid = None if invalid is None else np.asarray(invalid, dtype=bool)
        where = f"{path} channel {channel}"
        unit = opts.rate_unit or sig.unit
        if values.ndim != 1 or values.shape != stamps.shape:
            raise FogmonError(f"{where}: {values.shape} values for {stamps.shape} time stamps: not a rate channel")
        rate = values * dph_per_unit(unit, where)
        if invalid is not None and invalid.shape == rate.shape:
            rate = np.where(invalid, np.nan, rate)
        aux = _accelerometers(path, mdf, opts.accel_channels, stamps, names) if opts.accel_channels else None
        return StampedSource(stamps, rate, aux,
                             name=f"MDF4 {os.path.basename(path)} channel {channel} ({unit})", where=where,
                             time_field="time", meta={"sensor": f"{channel} ({unit})"},
                             max_abs_dph=opts.file_gate_dph, nominal_hz=opts.sample_rate_hz,
                             force_rate=opts.force_rate, resample_hz=opts.resample_hz)


def _accelerometers(path: str, mdf, spec: str, stamps: np.ndarray, names: list[str]) -> dict[str, np.ndarray]:
    """The accelerometer channels ``spec`` (``CHANNEL`` or ``AXIS=CHANNEL``, comma
    separated; plain ones named x, y, z in order) at the rate's time ``stamps`` as aux
    channels accel_<axis>_g (g)."""
    out: dict[str, np.ndarray] = {}
    for k, item in enumerate(c.strip() for c in spec.split(",")):
        axis, _, channel = item.rpartition("=") if "=" in item else ("xyz"[k] if k < 3 else f"a{k}", "", item)
        if not is_axis_name(axis) or f"accel_{axis}_g" in out:
            raise FogmonError(f"{path}: `accel_channels` {item!r}: the axis name must be letters and digits, once each")
        if channel not in mdf.channels_db:
            raise FogmonError(f"{path}: `accel_channels`: no channel {channel!r} in the file (it has: "
                              f"{point_to_info(path, 'channels', names)})")
        with reading(f"{path}: `accel_channels` {channel!r}"):
            sig = mdf.get(channel)
            values, t = np.asarray(sig.samples, dtype=np.float64), np.asarray(sig.timestamps, np.float64)
        scale = g_per_unit(sig.unit or "")
        if scale is None:
            raise FogmonError(f"{path} channel {channel}: unit {sig.unit!r} is not an acceleration unit fogmon knows "
                              f"({', '.join(G_PER_UNIT)})")
        if values.ndim != 1 or values.shape != t.shape:
            raise FogmonError(f"{path} channel {channel}: {values.shape} values for {t.shape} time stamps: not an "
                              f"accelerometer channel")
        out[f"accel_{axis}_g"] = nearest_samples(t, values * scale, stamps)
    return out

