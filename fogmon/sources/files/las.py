"""LAS (Log ASCII Standard) well logs, read with ``lasio`` (``fogmon[las]``), as downhole
memory tools write them.

A time curve (``time_channel``, default the index curve when its unit is a time: s,
ms, min, h) and a rate curve (``channel``, default the only curve whose unit is an
angular rate), units from the ~Curve section (``rate_unit`` overrides a missing or
wrong one). A depth-indexed file (index unit m or ft) is refused unless a time curve is
named; its depth then rides along as aux ``depth_m``. The only curve in deg C, if any,
becomes aux ``temp_c``. LAS null values are counted invalid samples (``null_samples``);
rows without a time are left out and counted (``rows_without_time``). Time stamps go on
fogmon's grid as fogmon.sources.files.stamped describes."""
from __future__ import annotations

import os

import numpy as np

from fogmon.errors import FogmonError
from fogmon.sources.files.stamped import StampedSource, dph_per_unit
from fogmon.sources.options import SourceOptions

#: time unit (lower case) -> s per unit
TIME_UNITS = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0,
              "hr": 3600.0}
#: temperature units (lower case) of a curve read as aux temp_c (deg C)
TEMP_UNITS = ("degc", "deg c", "c")
#: depth unit (lower case) -> m per unit
DEPTH_UNITS = {"m": 1.0, "meters": 1.0, "ft": 0.3048, "f": 0.3048, "feet": 0.3048}


def _is_rate(unit: str) -> bool:
    try:
        dph_per_unit(unit, "")
        return True
    except FogmonError:
        return False


def open_source(path: str, opts: SourceOptions) -> StampedSource:
    """The time and rate curves of the LAS file ``path`` as a StampedSource; a missing
    curve or a depth index without a time curve is a one-line FogmonError naming the
    file and the field."""
    las = _read(path)
    index = las.curves[0]
    tc, t_per = _time_curve(path, las, opts.time_channel)
    rc = _rate_curve(path, las, opts.channel)
    unit = opts.rate_unit or rc.unit
    where = f"{path} curve {rc.mnemonic}"
    factor = dph_per_unit(unit, where)
    t = np.asarray(tc.data, dtype=np.float64) * t_per
    has_t = np.isfinite(t)
    aux = {}
    if tc is not index and index.unit.lower() in DEPTH_UNITS:
        aux["depth_m"] = (np.asarray(index.data, dtype=np.float64) * DEPTH_UNITS[index.unit.lower()])[has_t]
    temps = [c for c in las.curves if c.unit.lower() in TEMP_UNITS]
    if len(temps) == 1:
        aux["temp_c"] = np.asarray(temps[0].data, dtype=np.float64)[has_t]
    return StampedSource(t[has_t], (np.asarray(rc.data, dtype=np.float64) * factor)[has_t], aux,
                         name=f"LAS {os.path.basename(path)} curve {rc.mnemonic} ({unit}) over {tc.mnemonic}",
                         where=where, time_field=f"curve {tc.mnemonic}", meta={"sensor": f"{rc.mnemonic} ({unit})"},
                         max_abs_dph=opts.file_gate_dph,
                         counters={"rows_without_time": int(np.count_nonzero(~has_t))} if not has_t.all() else None)


def _read(path: str):
    """The LAS file ``path`` read by lasio, with at least one curve."""
    import lasio
    try:
        las = lasio.read(path, ignore_header_errors=False)
    except Exception as e:  # lasio raises many error types for broken files
        why = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise FogmonError(f"{path}: not a readable LAS file ({why})") from None
    if not las.curves:
        raise FogmonError(f"{path}: no curves in the ~Curve section")
    return las


def _have(las) -> str:
    """The file's curves and their units, for error messages."""
    return ", ".join(f"{c.mnemonic} ({c.unit or 'no unit'})" for c in las.curves)


def _curve(path: str, las, name: str, what: str):
    """The curve ``name`` (given as option ``what``) of ``las``."""
    curves = {c.mnemonic: c for c in las.curves}
    if name not in curves:
        raise FogmonError(f"{path}: field {what}: no curve {name!r} in the file (it has: {_have(las)})")
    return curves[name]


def _time_curve(path: str, las, name: str | None):
    """The time curve (``name``, else the index curve if its unit is a time) and its s per unit."""
    index = las.curves[0]
    if name:
        tc = _curve(path, las, name, "time_channel")
    elif index.unit.lower() in TIME_UNITS:
        tc = index
    elif index.unit.lower() in DEPTH_UNITS:
        raise FogmonError(f"{path}: depth-indexed (index curve {index.mnemonic} in {index.unit}); the Allan "
                          f"deviation needs time: name the time curve with `time_channel` (curves: {_have(las)})")
    else:
        raise FogmonError(f"{path}: the index curve {index.mnemonic} has unit {index.unit!r}, not a time "
                          f"({', '.join(TIME_UNITS)}); name the time curve with `time_channel`")
    t_per = TIME_UNITS.get(tc.unit.lower())
    if t_per is None:
        raise FogmonError(f"{path}: field time_channel: curve {tc.mnemonic} has unit {tc.unit!r}, not a time "
                          f"({', '.join(TIME_UNITS)})")
    return tc, t_per


def _rate_curve(path: str, las, name: str | None):
    """The rate curve: ``name``, else the only curve with an angular-rate unit."""
    if name:
        return _curve(path, las, name, "channel")
    rates = [c for c in las.curves if _is_rate(c.unit)]
    if len(rates) != 1:
        raise FogmonError(f"{path}: {len(rates) or 'no'} curves with an angular-rate unit; name the rate "
                          f"curve with `channel` (curves: {_have(las)})")
    return rates[0]
