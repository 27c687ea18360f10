"""Allan-deviation curves other tools write (`fogmon fit`, docs/exports.md), read as
curves in fogmon's units: gyro ADEV in deg/h, accelerometer ADEV in micro-g.

The format is told by the file (``read_curves``):
- **CSV** (Stable32, MATLAB ``allanvar``, allantools, by hand): a header ``tau_s`` and one
  of ``adev_dph`` (a gyro, deg/h), ``adev_ug`` or ``adev_mps2`` (an accelerometer, micro-g
  or m/s^2), optionally ``edf`` or ``n_terms``; ``#`` comment lines, BOM and CRLF accepted.
- **imu_utils** (gaowenliang/imu_utils): ``data_<name>_<gyr|acc>_t.txt`` (tau, s, one per
  line) with ``_x.txt``, ``_y.txt``, ``_z.txt`` (ADEV per axis: gyro in deg/h computed
  with 57.3 deg/rad, accelerometer in m/s^2); any of these files names the set, and both
  kinds of the sensor are read when present (``sim_`` files: its fitted curves). Its
  taus are multiples m of the mean sample period measured from the stamps, m = 1 first:
  the rate is 1 / the first tau. Its estimator is the fully overlapping one; its largest
  m is the largest power of two <= N / 2 (N the record's samples), so N lies in
  2 m .. 4 m - 1.
- **allan_variance_ros** (ori-drs/allan_variance_ros, ``allan_variance.csv``): space
  separated rows ``tau acc_x acc_y acc_z gyro_x gyro_y gyro_z`` (s, m/s^2, deg/s), tau =
  0.1 .. 999.9 s in steps of 0.1 s; its estimator is the non-overlapping one over bins of
  tau x its measure_rate samples (neither the rate nor the record length is in the file);
  a row whose record held fewer than two bins has no value (NaN or 0) and is left out.
A bad file is a one-line FogmonError naming the file, the line and the column.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field

import numpy as np

from fogmon.errors import FogmonError
from fogmon.units import G0_MPS2, UG_PER_G

#: imu_utils's gyro ADEV is rad/s x 57.3 x 3600: x this to deg/h
IMU_UTILS_DPH = 180.0 / math.pi / 57.3
#: an imu_utils file name: data_<name>_[sim_]<gyr|acc>_<t|x|y|z>.txt
IMU_UTILS_NAME = re.compile(r"data_(?P<name>.+?)_(?P<sim>sim_)?(?P<kind>gyr|acc)_(?P<part>[txyz])\.txt")
#: the columns of an allan_variance_ros row after tau: (sensor, axis), m/s^2 and deg/s
AVR_COLUMNS = (("accel", "x"), ("accel", "y"), ("accel", "z"), ("gyro", "x"), ("gyro", "y"), ("gyro", "z"))
#: the ADEV column of a CSV curve -> (sensor, factor to deg/h or micro-g)
CSV_ADEV = {"adev_dph": ("gyro", 1.0), "adev_ug": ("accel", 1.0), "adev_mps2": ("accel", UG_PER_G / G0_MPS2)}


@dataclass(frozen=True)
class Curve:
    """One curve: ``sensor`` "gyro" (``adev`` in deg/h) or "accel" (micro-g), its axis
    (``axis``, "" when the file names none), ``tau_s`` (s, increasing), and what the
    file states per tau: ``n_terms`` or ``edf`` (None when not)."""

    sensor: str
    axis: str
    tau_s: np.ndarray
    adev: np.ndarray
    n_terms: np.ndarray | None = None
    edf: np.ndarray | None = None
    #: where each tau stands in the files ("FILE: line L"; empty: not known)
    rows: tuple[str, ...] = ()


@dataclass(frozen=True)
class CurveFile:
    """The curves of one file: ``fmt`` ("csv", "imu_utils", "allan_variance_ros"),
    ``files`` read, ``estimator`` ("overlapping" or "non-overlapping"), ``rate_hz`` the
    sample rate the file itself gives (None: it gives none), ``record_m`` (imu_utils: the
    record is 2 x .. 4 x this many samples; None), ``no_value_tau_s`` (allan_variance_ros:
    the first tau whose row had no value, so the record is at most 2 x it long; None) and
    ``notes``: what the format implies, as sentences for the output."""

    fmt: str
    files: tuple[str, ...]
    curves: list[Curve]
    estimator: str = "overlapping"
    rate_hz: float | None = None
    record_m: int | None = None
    notes: list[str] = field(default_factory=list)
    no_value_tau_s: float | None = None


def read_curves(path: str) -> CurveFile:
    """The Allan-deviation curves of ``path`` in any format the module docstring lists."""
    m = IMU_UTILS_NAME.fullmatch(os.path.basename(path))
    if m:
        return _imu_utils(path, m)
    lines = _text_lines(path)
    first = next((s.strip() for s in lines if s.strip() and not s.lstrip().startswith("#")), "")
    if "," not in first and len(first.split()) == 1 + len(AVR_COLUMNS) and _numbers(first.split()):
        return _allan_variance_ros(path, lines)
    return _csv(path, lines)


def _numbers(cells: list[str]) -> bool:
    try:
        [float(c) for c in cells]
    except ValueError:
        return False
    return True


def _text_lines(path: str) -> list[str]:
    """The lines of a UTF-8 text file (BOM and CRLF accepted), or a one-line FogmonError."""
    try:
        with open(path, encoding="utf-8-sig", newline=None) as fh:
            return fh.read().splitlines()
    except FileNotFoundError:
        raise FogmonError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise FogmonError(f"{path}: is a folder, not an Allan-deviation curve") from None
    except (OSError, UnicodeDecodeError) as e:
        raise FogmonError(f"{path}: cannot read: {getattr(e, 'strerror', None) or e}") from None


# -- imu_utils -------------------------------------------------------------------------------
def _imu_utils(path: str, m: re.Match) -> CurveFile:
    """The gyro and accelerometer curves of one imu_utils sensor (the files beside ``path``)."""
    folder, name, sim = os.path.dirname(path), m.group("name"), m.group("sim") or ""
    curves: list[Curve] = []
    files: list[str] = []
    absent: list[str] = []
    rate = None
    record_m = None
    for kind, sensor, scale, unit in (("gyr", "gyro", IMU_UTILS_DPH, "deg/h (57.3 deg/rad)"),
                                      ("acc", "accel", UG_PER_G / G0_MPS2, "m/s^2")):
        stem = os.path.join(folder, f"data_{name}_{sim}{kind}_")
        if not os.path.exists(stem + "t.txt"):
            if kind == m.group("kind"):
                raise FogmonError(f"{path}: imu_utils's tau file {stem}t.txt is missing (the taus of its _x, _y, "
                                  f"_z files)")
            continue
        tau, tau_lines = _column(stem + "t.txt", "tau_s")
        _check_taus(stem + "t.txt", tau, tau_lines)
        tau_rows = _rows(stem + "t.txt", tau_lines)
        files.append(stem + "t.txt")
        k = np.rint(tau / tau[0])
        rate = 1.0 / float(tau[0])
        record_m = int(k[-1])
        for axis in "xyz":
            f = stem + f"{axis}.txt"
            if not os.path.exists(f):
                absent.append(os.path.basename(f))
                continue
            adev, _ = _column(f, f"adev ({unit})")
            if len(adev) != len(tau):
                raise FogmonError(f"{f}: {len(adev)} values for the {len(tau)} taus of {stem}t.txt")
            files.append(f)
            curves.append(Curve(sensor, axis, tau, adev * scale, rows=tau_rows))
    if not curves:
        raise FogmonError(f"{path}: no imu_utils axis file (data_{name}_{sim}<gyr|acc>_<x|y|z>.txt) beside it")
    notes = ["imu_utils: fully overlapping estimator; taus are multiples of the mean sample period measured from "
             f"the time stamps, so the rate is 1 / the first tau = {rate:.10g} Hz",
             "imu_utils: gyro ADEV converted from its 57.3 deg/rad to deg/h (x 0.99992634); accelerometer ADEV from "
             "m/s^2 to micro-g (/ 9.80665e-6)"]
    if sim:
        notes.append("imu_utils sim_ files: these are imu_utils's own fitted curves, not measured ADEVs")
    if absent:
        which = "that axis is" if len(absent) == 1 else "those axes are"
        notes.append(f"imu_utils: no {', '.join(absent)} beside the tau file: {which} not fitted")
    return CurveFile("imu_utils", tuple(files), curves, "overlapping", rate, record_m, notes)


def _column(path: str, what: str) -> tuple[np.ndarray, list[int]]:
    """One number per line (blank lines skipped), each finite and > 0; and their lines."""
    vals, at = [], []
    for i, raw in enumerate(_text_lines(path), 1):
        s = raw.strip()
        if not s:
            continue
        try:
            x = float(s)
        except ValueError:
            raise FogmonError(f"{path}: line {i}, {what}: not a number: {s[:40]!r}") from None
        if not (math.isfinite(x) and x > 0):
            raise FogmonError(f"{path}: line {i}, {what}: must be a finite number > 0, got {s[:40]!r}")
        vals.append(x)
        at.append(i)
    if len(vals) < 2:
        raise FogmonError(f"{path}: needs at least 2 values, one per line ({what})")
    return np.array(vals), at


def _rows(path: str, lines: list[int]) -> tuple[str, ...]:
    """Where each value stands (``Curve.rows``): "FILE: line L" for each of ``lines``."""
    return tuple(f"{path}: line {i}" for i in lines)


def _check_taus(path: str, tau: np.ndarray, at: list[int]) -> None:
    bad = np.flatnonzero(np.diff(tau) <= 0)
    if len(bad):
        raise FogmonError(f"{path}: line {at[bad[0] + 1]}, tau_s: {tau[bad[0] + 1]:.10g} is not above the previous tau "
                          f"({tau[bad[0]]:.10g}): taus must increase")


# -- allan_variance_ros ----------------------------------------------------------------------
def _allan_variance_ros(path: str, lines: list[str]) -> CurveFile:
    """The six curves of an allan_variance_ros ``allan_variance.csv``."""
    rows, at = [], []
    for i, raw in enumerate(lines, 1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        cells = s.split()
        if len(cells) != 1 + len(AVR_COLUMNS):
            raise FogmonError(f"{path}: line {i}: {len(cells)} values, an allan_variance_ros row has "
                              f"{1 + len(AVR_COLUMNS)} (tau acc_x acc_y acc_z gyro_x gyro_y gyro_z)")
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            bad = next(j for j, c in enumerate(cells) if not _numbers([c]))
            name = "tau" if bad == 0 else "_".join(AVR_COLUMNS[bad - 1])
            raise FogmonError(f"{path}: line {i}, column {name}: not a number: {cells[bad][:40]!r}") from None
        at.append(i)
    a = np.array(rows)
    tau = a[:, 0]
    # no value: NaN (0/0) or a zero (sqrt(-0)), as allan_variance_ros writes where a tau has too few bins;
    # anything else not > 0 is a bad cell
    wrong = np.argwhere(np.isinf(a[:, 1:]) | (a[:, 1:] < 0))
    if len(wrong):
        r, j = wrong[0]
        raise FogmonError(f"{path}: line {at[r]}, column {'_'.join(AVR_COLUMNS[j])}: must be > 0 (or nan or 0 "
                          f"where allan_variance_ros has no value), got {float(a[r, 1 + j])!r}")
    ok = np.all(np.isfinite(a[:, 1:]) & (a[:, 1:] > 0), axis=1)
    bad_tau = np.flatnonzero(~(np.isfinite(tau) & (tau > 0)))
    if len(bad_tau):
        raise FogmonError(f"{path}: line {at[bad_tau[0]]}, column tau: must be a finite number > 0")
    back = np.flatnonzero(np.diff(tau) <= 0)
    if len(back):
        raise FogmonError(f"{path}: line {at[back[0] + 1]}, column tau: {tau[back[0] + 1]:g} is not above the "
                          f"previous tau ({tau[back[0]]:g}): taus must increase")
    notes = ["allan_variance_ros: non-overlapping estimator (bins of tau x its measure_rate samples); accelerometer "
             "ADEV from m/s^2 to micro-g, gyro ADEV from deg/s to deg/h"]
    if not ok.all():
        first_bad = int(np.argmax(~ok))
        if ok[first_bad:].any():
            j = first_bad + int(np.argmax(ok[first_bad:]))
            raise FogmonError(f"{path}: line {at[first_bad]}: no value at tau {tau[first_bad]:g} s but one at "
                              f"{tau[j]:g} s (line {at[j]}): not what allan_variance_ros writes")
        notes.append(f"allan_variance_ros: the {len(tau) - first_bad} rows from tau {tau[first_bad]:g} s on have no "
                     f"value (the record held fewer than two bins of them): left out")
    if ok.sum() < 2:
        raise FogmonError(f"{path}: fewer than 2 rows with values")
    tau_ok = tau[ok]
    rows_ok = _rows(path, [i for i, good in zip(at, ok, strict=True) if good])
    curves = [Curve(sensor, axis, tau_ok, a[ok, 1 + j] * (UG_PER_G / G0_MPS2 if sensor == "accel" else 3600.0),
                    rows=rows_ok)
              for j, (sensor, axis) in enumerate(AVR_COLUMNS)]
    no_value = float(tau[int(np.argmax(~ok))]) if not ok.all() else None
    return CurveFile("allan_variance_ros", (path,), curves, "non-overlapping", notes=notes, no_value_tau_s=no_value)


# -- CSV ---------------------------------------------------------------------------------
def _csv(path: str, lines: list[str]) -> CurveFile:
    """One curve of a CSV file (the module docstring)."""
    cols: list[str] | None = None
    rows: list[list[float]] = []
    at: list[int] = []
    for i, raw in enumerate(lines, 1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        if cols is None:
            cols = _csv_header(cells, path, i)
            continue
        row = _csv_row(cols, cells, path, i)
        t = cols.index("tau_s")
        if rows and row[t] <= rows[-1][t]:
            raise FogmonError(f"{path}: line {i}, column tau_s: {row[t]:g} is not above the "
                              f"previous tau ({rows[-1][t]:g}): taus must increase")
        rows.append(row)
        at.append(i)
    if cols is None or len(rows) < 2:
        raise FogmonError(f"{path}: needs a header (tau_s,adev_dph[,edf|n_terms]; adev_ug or adev_mps2 for an "
                          f"accelerometer) and at least 2 rows")
    a = np.array(rows, dtype=np.float64)
    c = {name: a[:, j] for j, name in enumerate(cols)}
    adev_col = next(n for n in cols if n in CSV_ADEV)
    sensor, scale = CSV_ADEV[adev_col]
    return CurveFile("csv", (path,), [Curve(sensor, "", c["tau_s"], c[adev_col] * scale, c.get("n_terms"),
                                            c.get("edf"), _rows(path, at))])


def _csv_header(cols: list[str], path: str, i: int) -> list[str]:
    """The header's columns, checked: tau_s and one ADEV column, optionally edf or n_terms."""
    adev = [c for c in cols if c in CSV_ADEV]
    if "tau_s" not in cols or len(adev) != 1:
        what = (f"no column {'tau_s' if 'tau_s' not in cols else 'adev_dph'}" if "tau_s" not in cols or not adev
                else f"{len(adev)} ADEV columns ({', '.join(adev)}), a curve file holds one")
        raise FogmonError(f"{path}: line {i}: header has {what} (columns: tau_s,adev_dph "
                          f"and optionally edf or n_terms; adev_ug or adev_mps2 for an accelerometer)")
    known = ("tau_s", *CSV_ADEV, "edf", "n_terms")
    unknown = [c for c in cols if c not in known]
    if unknown or len(set(cols)) != len(cols):
        raise FogmonError(f"{path}: line {i}: column {(unknown or cols)[0]!r}: unknown or repeated (columns: "
                          f"tau_s, adev_dph, edf, n_terms)")
    if "edf" in cols and "n_terms" in cols:
        raise FogmonError(f"{path}: line {i}: columns edf and n_terms: give one of them")
    return cols


def _csv_row(cols: list[str], cells: list[str], path: str, i: int) -> list[float]:
    """One data row's values, checked cell by cell (n_terms whole >= 1, the others > 0)."""
    if len(cells) != len(cols):
        raise FogmonError(f"{path}: line {i}: {len(cells)} cells, the header has {len(cols)}")
    row = []
    for c, v in zip(cols, cells, strict=True):
        try:
            x = float(v)
        except ValueError:
            raise FogmonError(f"{path}: line {i}, column {c}: not a number: {v[:40]!r}") from None
        bad = (not np.isfinite(x) or x < 1 or not float(x).is_integer() if c == "n_terms" else
               not np.isfinite(x) or x <= 0)
        if bad:
            need = "a whole number >= 1" if c == "n_terms" else "a finite number > 0"
            raise FogmonError(f"{path}: line {i}, column {c}: must be {need}, got {v[:40]!r}")
        row.append(x)
    return row
