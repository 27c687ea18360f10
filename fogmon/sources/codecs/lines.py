"""Generic ASCII/CSV lines with a column map: what a home-built MWD board or a
microcontroller prints, one sample per line, fields separated by commas, semicolons,
tabs or spaces.

The column map (``columns``) names each field in order:

- the rate, exactly one of ``rate_dph`` (deg/h), ``rate_dps`` (deg/s), ``rate_rps``
  (rad/s), ``delta_deg``, ``delta_rad``, ``delta_arcsec`` (angle per sample); or one
  per axis, the axis name (letters/digits) inside the name: ``rate_x_dph``,
  ``rate_y_dps``, ``delta_z_rad``, ... (each in its own unit). Two or more give a
  multi-axis stream (axes in column order; ``axis`` picks some of them, one picked = a
  one-axis stream), a single one a one-axis stream;
- ``valid_<axis>`` (nonzero = that axis's sample is good), beside ``valid`` (all axes);
- ``seq`` (unbounded sample counter) or ``seq:N`` (counter wrapping at N), used for gap
  detection;
- ``valid`` (nonzero = good sample);
- ``-`` or ``_`` to ignore a field (a device clock, a checksum you do not check, ...);
- any other name is an auxiliary channel carried along in the units its name says
  (``temp_c``, ``vib_g``, ``rot_dps``, ``depth_m`` have fixed meanings).

Lines that do not parse (boot banners, a header row, truncated lines) are counted as
``bad_lines``, their bytes as ``bytes_skipped``. A rate beyond ``max_rate_dph`` (default
the generic gate of fogmon.sources.plausibility, 10,000 deg/s) makes the sample invalid,
counted as ``implausible_samples``.
"""
from __future__ import annotations

import math
import re

from fogmon import units
from fogmon.errors import FogmonError
from fogmon.sources import plausibility
from fogmon.sources.codecs.framing import LineFramer
from fogmon.sources.frames import Frames
from fogmon.sources.grid import check_sample_rate

DEFAULT_RATE_HZ = 100.0
#: rate column name -> its unit (fogmon.units): a rate, or an angle per sample
RATE_COLUMNS = {"rate_dph": "deg/h", "rate_dps": "deg/s", "rate_rps": "rad/s", "delta_deg": "deg",
                "delta_rad": "rad", "delta_arcsec": "arcsec"}
_SPLIT = re.compile(rb"[,;\s]+")
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
#: a per-axis rate column: rate_<axis>_dph, delta_<axis>_rad, ...
_AXIS_RATE = re.compile(r"^(rate|delta)_([A-Za-z0-9]+)_([a-z]+)$")


def rate_column(name: str) -> tuple[str, str] | None:
    """(axis, fogmon.units unit) of a rate column name (axis "" for the plain names of
    RATE_COLUMNS), None for any other name."""
    if name in RATE_COLUMNS:
        return "", RATE_COLUMNS[name]
    m = _AXIS_RATE.match(name)
    base = f"{m.group(1)}_{m.group(3)}" if m else ""
    return (m.group(2), RATE_COLUMNS[base]) if m and base in RATE_COLUMNS else None


def parse_columns(spec: str) -> tuple[list[str], int | None]:
    """``'seq:256,rate_dps,temp_c,-'`` -> (names, seq modulus). Raises FogmonError naming
    the bad field."""
    names, modulus = [], None
    for i, f in enumerate((f.strip() for f in spec.split(",")), 1):
        name, mod = _column(i, f)
        names.append(name)
        modulus = mod or modulus
    real = [n for n in names if n != "-"]
    dup = {n for n in real if real.count(n) > 1}
    if dup:
        raise FogmonError(f"`columns` names {', '.join(sorted(dup))} more than once")
    rates = [r for r in map(rate_column, names) if r is not None]
    axes = [a for a, _ in rates]
    if not rates or ("" in axes and len(rates) > 1) or len(set(axes)) != len(axes):
        raise FogmonError(f"`columns` needs exactly one rate column (one of {', '.join(RATE_COLUMNS)}) or one per "
                          f"axis (rate_x_dph, rate_y_dps, ...), got {spec!r}")
    return names, modulus


def _column(i: int, f: str) -> tuple[str, int | None]:
    """The column name of ``columns`` field ``i`` (1-based) ``f`` ("-" ignored, "seq" the
    counter) and the counter's modulus if ``f`` gives one."""
    if f in ("-", "_"):
        return "-", None
    if f == "seq":
        return "seq", None
    if f.startswith("seq"):
        m = re.fullmatch(r"seq:(\d+)", f)
        if not m or int(m.group(1)) < 2:
            raise FogmonError(f"`columns` field {i} {f!r}: write seq or seq:N with N >= 2")
        return "seq", int(m.group(1))
    if f == "time_s" or not _NAME.match(f):
        raise FogmonError(f"`columns` field {i} {f!r}: not a usable column name "
                          f"(time comes from `sample_rate_hz` and the counter; use - to ignore a field)")
    return f, None


def _picked_axes(by_axis: dict[str, tuple[str, str]], axis: str | None, columns: str) -> list[str]:
    """The axes decoded: those of ``axis`` (comma-separated), else every rate
    column's axis of ``by_axis`` (axis -> (column, unit); "" for a one-axis log)."""
    picked = list(by_axis) if axis is None or "" in by_axis else axis.split(",")
    missing = [a for a in picked if a not in by_axis]
    if missing:
        raise FogmonError(f"`axis` {axis}: `columns` {columns!r} has no rate column of axis "
                          f"{', '.join(missing)} (it has: {', '.join(by_axis)})")
    return picked


class LinesCodec:
    """Incremental decoder for column-mapped lines. Counters: ``frames_ok``,
    ``bad_lines``, ``bytes_skipped``, ``implausible_samples`` (valid samples whose rate
    is beyond ``max_rate_dph`` deg/h, None = plausibility.GENERIC_MAX_ABS_DPH)."""

    protocol = "lines"

    def __init__(self, columns: str = "rate_dph", sample_rate_hz: float = DEFAULT_RATE_HZ,
                 max_rate_dph: float | None = None, axis: str | None = None) -> None:
        sample_rate_hz = check_sample_rate(sample_rate_hz)
        self.columns, self.sample_rate_hz = columns, float(sample_rate_hz)
        self.max_rate_dph = plausibility.max_rate_dph(max_rate_dph, plausibility.GENERIC_MAX_ABS_DPH)
        self._names, mod = parse_columns(columns)
        has_seq = "seq" in self._names
        self.seq_modulus = (mod or 2 ** 62) if has_seq else None
        rates = {n: r for n in self._names if (r := rate_column(n)) is not None}
        by_axis = {a: (n, u) for n, (a, u) in rates.items()}
        picked = _picked_axes(by_axis, axis, columns)
        self.axes: tuple[str, ...] = tuple(picked) if len(picked) > 1 else ()
        self._rates = [(by_axis[a][0], units.dph_scale(by_axis[a][1], self.sample_rate_hz),
                        f"valid_{a}" if f"valid_{a}" in self._names else None) for a in picked]
        self.axis = None if axis is None or "" in by_axis else ",".join(picked)
        own = set(rates) | {f"valid_{a}" for a in by_axis if a}
        self.aux_names = tuple(n for n in self._names if n not in ("-", "seq", "valid") and n not in own)
        self._framer = LineFramer(512)
        self.counters = {"frames_ok": 0, "bad_lines": 0, "bytes_skipped": 0, plausibility.COUNTER: 0}

    @property
    def pending(self) -> int:
        return self._framer.pending

    def options(self) -> dict:
        opts = {"protocol": self.protocol, "columns": self.columns, "sample_rate_hz": self.sample_rate_hz,
                "max_rate_dph": self.max_rate_dph}
        return opts if self.axis is None else {**opts, "axis": self.axis}

    def describe(self) -> str:
        what = f", axes {','.join(self.axes)}" if self.axes else (f", axis {self.axis}" if self.axis else "")
        return f"ASCII lines [{self.columns}]{what}, {self.sample_rate_hz:g} Hz"

    def feed(self, data: bytes) -> Frames:
        fr = self._framer
        before = fr.dropped_bytes, fr.dropped_lines
        names, ncol = self._names, len(self._names)
        seq, rate, valid = [], [], []
        aux: dict[str, list[float]] = {k: [] for k in self.aux_names}
        bad = bad_bytes = 0
        mod = self.seq_modulus
        for line in fr.feed(data):
            cells = _SPLIT.split(line.strip())
            row = {}
            try:
                if len(cells) != ncol:
                    raise ValueError
                for name, cell in zip(names, cells, strict=True):
                    if name == "-":
                        continue
                    v = float(cell)
                    if not math.isfinite(v):
                        raise ValueError
                    row[name] = v
                if "seq" in row and (row["seq"] != int(row["seq"]) or row["seq"] < 0):
                    raise ValueError
            except ValueError:
                if line.strip():
                    bad += 1
                bad_bytes += len(line)
                continue
            seq.append(int(row["seq"]) % mod if mod else -1)
            ok = row.get("valid", 1.0) != 0
            rate.append([row[n] * scale for n, scale, _ in self._rates])
            valid.append([ok and (v is None or row[v] != 0) for _, _, v in self._rates])
            for k in self.aux_names:
                aux[k].append(row[k])
        c = self.counters
        c["frames_ok"] += len(rate)
        c["bad_lines"] += bad + fr.dropped_lines - before[1]
        c["bytes_skipped"] += bad_bytes + fr.dropped_bytes - before[0]
        rate_dph, n = plausibility.gate(rate, self.max_rate_dph, valid)
        c[plausibility.COUNTER] += n
        return Frames.from_lists(seq, rate_dph, valid, aux, axes=self.axes)
