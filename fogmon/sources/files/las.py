"""LAS (Log ASCII Standard) well logs, read with ``lasio`` (``fogmon[las]``), as downhole
memory tools write them.

A time curve (``time_channel``, default the index curve when it is a time: unit s, ms,
min, h; or a clock: unit HHMMSS / values ``hh:mm:ss``, with the day from a date curve
(unit D or named DATE) when there is one and past midnight otherwise; or date-times
``2020-01-01T00:00:00``, ``01-JAN-2020 00:00:00``: ``clock_seconds``) and a rate curve
(``channel``, default the only curve whose unit is an angular rate), units from the
~Curve section (``rate_unit`` overrides a missing or wrong one). A depth-indexed file
(index unit m or ft) is refused unless a time curve is named; its depth then rides along
as aux ``depth_m``. The only curve in deg C, if any, becomes aux ``temp_c``. LAS null
values are counted invalid samples (``null_samples``); rows without a time are left out
and counted (``rows_without_time``). Time stamps go on fogmon's grid as
fogmon.sources.files.stamped describes."""
from __future__ import annotations

import os
import re
from datetime import datetime

import numpy as np

from fogmon.errors import FogmonError
from fogmon.sources.files.listing import Entry, reading, stamped_entry
from fogmon.sources.files.stamped import StampedSource, dph_per_unit
from fogmon.sources.options import SourceOptions

#: time unit (lower case) -> s per unit
TIME_UNITS = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0,
              "hr": 3600.0}
#: temperature units (lower case) of a curve read as aux temp_c (deg C)
TEMP_UNITS = ("degc", "deg c", "c")
#: depth unit (lower case) -> m per unit
DEPTH_UNITS = {"m": 1.0, "meters": 1.0, "ft": 0.3048, "f": 0.3048, "feet": 0.3048}
#: units of a clock-time curve (time of day)
CLOCK_UNITS = ("hhmmss", "hh:mm:ss", "hhmmss.s", "time")
#: date formats of date and date-time curves (a time of day may follow, see _DATETIME)
DATE_FORMATS = ("%Y-%m-%d", "%d-%b-%y", "%d-%b-%Y", "%d/%m/%Y", "%m/%d/%Y", "%Y/%m/%d", "%d.%m.%Y", "%Y%m%d")
_CLOCK = re.compile(r"(\d{1,2}):?(\d\d):?(\d\d(?:\.\d*)?)")
_DATETIME = re.compile(r"(.+?)[ T](\d{1,2}:\d\d:\d\d(?:\.\d*)?)")


def _is_rate(unit: str) -> bool:
    try:
        dph_per_unit(unit, "")
        return True
    except FogmonError:
        return False


def _day_seconds(text: str) -> float | None:
    """Seconds since 0001-01-01 of a date ``text`` in one of DATE_FORMATS, else None."""
    for f in DATE_FORMATS:
        try:
            d = datetime.strptime(text, f)
        except ValueError:
            continue
        return (d - datetime(1, 1, 1)).total_seconds()
    return None


def _clock(text: str) -> float | None:
    """Seconds of a time of day ``hh:mm:ss[.f]`` or ``hhmmss[.f]``, else None."""
    m = _CLOCK.fullmatch(text)
    if not m or int(m.group(2)) > 59 or float(m.group(3)) >= 61:
        return None
    return int(m.group(1)) * 3600.0 + int(m.group(2)) * 60.0 + float(m.group(3))


def _instant(text: str) -> float | None:
    """Seconds since 0001-01-01 of a date-time ``text`` (ISO, or a DATE_FORMATS date and
    a time of day), else None."""
    try:
        d = datetime.fromisoformat(text)
        return (d.replace(tzinfo=None) - datetime(1, 1, 1)).total_seconds()
    except ValueError:
        pass
    m = _DATETIME.fullmatch(text)
    if m:
        day, clock = _day_seconds(m.group(1)), _clock(m.group(2))
        if day is not None and clock is not None:
            return day + clock
    return None


def clock_seconds(values, unit: str, dates=None) -> np.ndarray | None:
    """Seconds (from the first value) of a time curve written as clock times or
    date-times (see the module docstring): NaN where a value is not one (a null); None
    when the curve is none of these. A time of day with ``dates`` (the date curve's
    values) is placed on its day; without, a step back by more than 12 h is the next
    day."""
    arr = np.asarray(values)
    if arr.dtype.kind in "fiu" and unit.lower() in CLOCK_UNITS:     # hhmmss as a number: 235959.5
        v = arr.astype(np.float64)
        h, rest = np.divmod(v, 10000.0)
        m, sec = np.divmod(rest, 100.0)
        good = (m < 60) & (sec < 61) & (v >= 0)
        texts = [f"{int(a):02d}:{int(b):02d}:{c:09.6f}" if g and np.isfinite(x) else ""
                 for a, b, c, g, x in zip(h, m, sec, good, v, strict=True)]
    else:
        texts = ["" if x is None else str(x).strip() for x in np.asarray(values, dtype=object)]
    if unit.lower() in CLOCK_UNITS or any(":" in x for x in texts):
        clock = [_clock(x) if x else None for x in texts]
        if sum(c is not None for c in clock) > len(texts) // 2:
            sec = np.array([np.nan if c is None else c for c in clock])
            day = None if dates is None else [_day_seconds(str(d).strip()) for d in dates]
            if day is not None and all(d is not None for d in day):
                sec = sec + np.array(day, dtype=np.float64)
            else:
                ok = np.isfinite(sec)
                back = np.zeros(len(sec))
                back[np.flatnonzero(ok)[1:]] = np.diff(sec[ok]) < -43200.0
                sec = sec + 86400.0 * np.cumsum(back)
            return sec - sec[np.isfinite(sec)][0]
    stamps = [_instant(x) if x else None for x in texts]
    if sum(s is not None for s in stamps) > len(texts) // 2:
        sec = np.array([np.nan if s is None else s for s in stamps])
        return sec - sec[np.isfinite(sec)][0]
    return None


def _date_curve(las):
    """The date curve (unit D or named DATE), if there is exactly one."""
    dates = [c for c in las.curves if c.unit.lower() in ("d", "date") or c.mnemonic.upper() == "DATE"]
    return dates[0] if len(dates) == 1 else None


def _times(las, tc, t_per: float | None) -> np.ndarray:
    """The time curve's values in s."""
    if t_per is not None:
        return np.asarray(tc.data, dtype=np.float64) * t_per
    date = _date_curve(las)
    sec = clock_seconds(tc.data, tc.unit, None if date is None or date is tc else date.data)
    assert sec is not None  # _time_curve checked it
    return sec


def info(path: str, opts: SourceOptions) -> list[Entry]:
    """One Entry per curve of the LAS file ``path`` (rate and span from the time curve
    when the file has one: ``time_channel`` or a time index)."""
    las = _read(path)
    try:
        tc, t_per = _time_curve(path, las, opts.time_channel)
        t = _times(las, tc, t_per)
    except FogmonError:
        t = None
    out = []
    for c in las.curves:
        data = np.asarray(c.data)
        if data.dtype.kind == "f":
            ok = np.isfinite(data)
        else:
            ok = np.array([str(v).strip() not in ("", "nan") for v in data], dtype=bool)
        stamps = t[ok] if t is not None and len(t) == len(ok) else np.full(int(ok.sum()), np.nan)
        e = stamped_entry(c.mnemonic, "curve", stamps, c.unit)
        out.append(Entry(e.name, e.type, int(ok.sum()), e.rate_hz, e.span_s, e.unit))
    return out


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
    t = _times(las, tc, t_per)
    has_t = np.isfinite(t)
    aux = {}
    if tc is not index and index.unit.lower() in DEPTH_UNITS:
        aux["depth_m"] = (np.asarray(index.data, dtype=np.float64) * DEPTH_UNITS[index.unit.lower()])[has_t]
    temps = [c for c in las.curves if c.unit.lower() in TEMP_UNITS]
    if len(temps) == 1:
        aux["temp_c"] = np.asarray(temps[0].data, dtype=np.float64)[has_t]
    try:
        values = np.asarray(rc.data, dtype=np.float64)
    except ValueError:
        raise FogmonError(f"{where}: values are not numbers (the rate curve must be numeric)") from None
    return StampedSource(t[has_t], (values * factor)[has_t], aux,
                         name=f"LAS {os.path.basename(path)} curve {rc.mnemonic} ({unit}) over {tc.mnemonic}",
                         where=where, time_field=f"curve {tc.mnemonic}", meta={"sensor": f"{rc.mnemonic} ({unit})"},
                         max_abs_dph=opts.file_gate_dph,
                         counters={"rows_without_time": int(np.count_nonzero(~has_t))} if not has_t.all() else None,
                         nominal_hz=opts.sample_rate_hz, force_rate=opts.force_rate, resample_hz=opts.resample_hz)


def _read(path: str):
    """The LAS file ``path`` read by lasio, with at least one curve."""
    import lasio
    with reading(f"{path}: not a readable LAS file"):   # lasio raises many error types for broken files
        las = lasio.read(path, ignore_header_errors=False)
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
        raise FogmonError(f"{path}: `{what}`: no curve {name!r} in the file (it has: {_have(las)})")
    return curves[name]


def _time_curve(path: str, las, name: str | None):
    """The time curve (``name``, else the index curve if it is a time) and its s per unit
    (None: clock times or date-times, ``clock_seconds``)."""
    index = las.curves[0]
    if name:
        tc = _curve(path, las, name, "time_channel")
    elif index.unit.lower() in TIME_UNITS or clock_seconds(index.data, index.unit) is not None:
        tc = index
    elif index.unit.lower() in DEPTH_UNITS:
        raise FogmonError(f"{path}: depth-indexed (index curve {index.mnemonic} in {index.unit}); the Allan "
                          f"deviation needs time: name the time curve with `time_channel` (curves: {_have(las)})")
    else:
        raise FogmonError(f"{path}: the index curve {index.mnemonic} has unit {index.unit!r}, not a time "
                          f"({', '.join(TIME_UNITS)}); name the time curve with `time_channel`")
    t_per = TIME_UNITS.get(tc.unit.lower())
    if t_per is None and clock_seconds(tc.data, tc.unit) is None:
        raise FogmonError(f"{path}: `time_channel`: curve {tc.mnemonic} has unit {tc.unit!r}, not a time "
                          f"({', '.join(TIME_UNITS)}, a clock hh:mm:ss or date-times)")
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
