"""ASAM MDF4 measurement files, read with ``asammdf`` (``fogmon[mdf]``).

``channel`` NAME: a rate channel, its unit from the file (deg/h, deg/s, rad/s, ...;
``rate_unit`` when the file has none), its own time stamps (s) on fogmon's grid as
fogmon.sources.files.timing describes. Raw CAN frames in the MDF bus-logging format are a
CAN log instead: give ``dbc`` (fogmon.sources.files.can_log, through python-can's MF4
reader)."""
from __future__ import annotations

import os

import numpy as np

from fogmon.errors import FogmonError
from fogmon.sources.files.listing import Entry, point_to_info, reading, stamped_entry
from fogmon.sources.files.stamped import StampedSource, dph_per_unit
from fogmon.sources.options import SourceOptions

#: names of the master (time) channel, not listed as data
MASTER_NAMES = ("t", "time")


def _read(path: str):
    import asammdf
    with reading(f"{path}: not a readable MDF file"):   # asammdf raises MdfException and plain errors
        return asammdf.MDF(path)
    raise AssertionError("unreachable")


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
        return StampedSource(stamps, rate, None,
                             name=f"MDF4 {os.path.basename(path)} channel {channel} ({unit})", where=where,
                             time_field="time", meta={"sensor": f"{channel} ({unit})"},
                             max_abs_dph=opts.file_gate_dph, nominal_hz=opts.sample_rate_hz,
                             force_rate=opts.force_rate, resample_hz=opts.resample_hz)
