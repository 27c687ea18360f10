"""ASAM MDF4 measurement files, read with ``asammdf`` (``fogmon[mdf]``).

``channel`` NAME: a rate channel, its unit from the file (deg/h, deg/s, rad/s, ...;
``rate_unit`` when the file has none), its own time stamps (s) on fogmon's grid as
fogmon.sources.files.stamped describes. Raw CAN frames in the MDF bus-logging format are a CAN
log instead: give ``dbc`` (fogmon.sources.files.can_log, through python-can's MF4 reader)."""
from __future__ import annotations

import os

import numpy as np

from fogmon.errors import FogmonError
from fogmon.sources.files.stamped import StampedSource, dph_per_unit
from fogmon.sources.options import SourceOptions

#: channel names listed in an error before the rest are only counted
SHOWN_CHANNELS = 12


def open_source(path: str, opts: SourceOptions) -> StampedSource:
    """Channel ``opts.channel`` of the MDF file ``path`` as a StampedSource; a
    missing channel is a one-line FogmonError naming the file and listing channels."""
    import asammdf
    try:
        mdf = asammdf.MDF(path)
    except Exception as e:  # asammdf raises MdfException and plain errors for broken files
        why = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise FogmonError(f"{path}: not a readable MDF file ({why})") from None
    with mdf:
        names = sorted(n for n in mdf.channels_db if n not in ("t", "time"))  # not the master time
        channel = opts.channel
        shown = ", ".join(names[:SHOWN_CHANNELS]) + (f" and {len(names) - SHOWN_CHANNELS} more"
                                                     if len(names) > SHOWN_CHANNELS else "")
        if not channel:
            raise FogmonError(f"{path}: an MDF4 file needs `channel` NAME (the rate channel; it has: {shown}) or "
                              f"`dbc` F for raw CAN frames")
        if channel not in mdf.channels_db:
            raise FogmonError(f"{path}: field channel: no channel {channel!r} in the file (it has: {shown})")
        try:
            sig = mdf.get(channel)
        except Exception as e:  # several groups hold the name, or the channel cannot be decoded
            raise FogmonError(f"{path}: field channel: {channel!r}: {str(e).splitlines()[0]}") from None
        where = f"{path} channel {channel}"
        unit = opts.rate_unit or sig.unit
        factor = dph_per_unit(unit, where)
        rate = np.asarray(sig.samples, dtype=np.float64) * factor
        invalid = getattr(sig, "invalidation_bits", None)   # samples the logger marked invalid
        if invalid is not None:
            rate = np.where(np.asarray(invalid, dtype=bool), np.nan, rate)
        return StampedSource(np.asarray(sig.timestamps, dtype=np.float64), rate, None,
                             name=f"MDF4 {os.path.basename(path)} channel {channel} ({unit})", where=where,
                             time_field="time", meta={"sensor": f"{channel} ({unit})"},
                             max_abs_dph=opts.file_gate_dph)
