"""Replay log v1 (CONTRACT section 1): the CSV recording format every command reads,
and `fogmon monitor`/`fogmon sim` write. Parsing is strict: a bad cell, NaN/inf, time
going backwards or repeating is a one-line error naming file, line and column, unless
the caller asks to tolerate bad rows, in which case they are skipped and counted."""
from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass, field

import numpy as np

from fogmon.block import Block
from fogmon.errors import FogmonError

MAGIC = "# fogmon replay log v1"
REQUIRED = ("time_s", "rate_dph")


@dataclass
class Recording:
    """A whole recording in memory: ``t_s`` (s), ``rate_dph`` (deg/h), auxiliary
    channels by column name, ``meta`` from ``# key: value`` lines, and how many bad
    rows were skipped when reading tolerantly."""

    t_s: np.ndarray
    rate_dph: np.ndarray
    aux: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, str] = field(default_factory=dict)
    path: str | None = None
    skipped_rows: int = 0

    @property
    def name(self) -> str:
        return os.path.basename(self.path) if self.path else "<memory>"

    @property
    def sample_rate_hz(self) -> float:
        """Nominal sample rate in Hz: the ``sample_rate_hz`` metadata when present,
        otherwise 1 / median sample interval."""
        if "sample_rate_hz" in self.meta:
            try:
                fs = float(self.meta["sample_rate_hz"])
            except ValueError:
                raise FogmonError(f"{self.name}: metadata sample_rate_hz is not a number: "
                                  f"{self.meta['sample_rate_hz']!r}") from None
            if not (fs > 0 and math.isfinite(fs)):
                raise FogmonError(f"{self.name}: metadata sample_rate_hz must be > 0, got {fs}")
            return fs
        if len(self.t_s) < 2:
            raise FogmonError(f"{self.name}: too few samples to know the sample rate")
        return 1.0 / float(np.median(np.diff(self.t_s)))

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0]) + 1.0 / self.sample_rate_hz if len(self.t_s) else 0.0

    def __len__(self) -> int:
        return len(self.t_s)

    def grid_index(self) -> np.ndarray:
        """Index of every sample on the uniform grid t0 + k / fs. Samples more than a
        quarter period off the grid, or two samples in one period, are an error."""
        fs = self.sample_rate_hz
        k = (self.t_s - self.t_s[0]) * fs
        idx = np.rint(k).astype(np.int64)
        off = np.abs(k - idx)
        if len(off) and off.max() > 0.25:
            i = int(np.argmax(off))
            raise FogmonError(f"{self.name}: sample at time_s={self.t_s[i]!r} is {off[i]:.2f} sample "
                              f"periods off the {fs:g} Hz grid (is sample_rate_hz right?)")
        if len(idx) > 1 and np.any(np.diff(idx) < 1):
            i = int(np.argmax(np.diff(idx) < 1)) + 1
            raise FogmonError(f"{self.name}: two samples within one {1 / fs:g} s period at "
                              f"time_s={self.t_s[i]!r}")
        return idx

    def to_block(self) -> Block:
        """The recording on its uniform sample grid: missing samples (time gaps) become
        invalid placeholders (rate and aux NaN), so gaps are never joined."""
        idx = self.grid_index()
        n = int(idx[-1]) + 1 if len(idx) else 0
        fs = self.sample_rate_hz
        t = self.t_s[0] + np.arange(n) / fs if n else np.zeros(0)
        if n == len(idx):
            return Block.make(self.t_s.copy(), self.rate_dph.copy(), aux={k: v.copy() for k, v in self.aux.items()})
        t[idx] = self.t_s
        rate = np.full(n, np.nan)
        rate[idx] = self.rate_dph
        aux = {}
        for k, v in self.aux.items():
            a = np.full(n, np.nan)
            a[idx] = v
            aux[k] = a
        return Block.make(t, rate, aux=aux)


def _parse_header(lines_iter, name: str):
    """Read comment/metadata lines and the header. Returns (meta, columns, header_line_no)."""
    meta: dict[str, str] = {}
    for lineno, line in lines_iter:
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            body = s[1:].strip()
            if ":" in body and not body.lower().startswith("fogmon replay log"):
                k, v = body.split(":", 1)
                if k.strip() and " " not in k.strip():
                    meta[k.strip()] = v.strip()
            continue
        cols = [c.strip() for c in s.split(",")]
        for req in REQUIRED:
            if req not in cols:
                raise FogmonError(f"{name}: line {lineno}: missing required column {req!r} "
                                  f"(header has: {', '.join(cols)})")
        seen = set()
        for c in cols:
            if not c:
                raise FogmonError(f"{name}: line {lineno}: empty column name in header")
            if c in seen:
                raise FogmonError(f"{name}: line {lineno}: duplicated column {c!r}")
            seen.add(c)
        return meta, cols, lineno
    raise FogmonError(f"{name}: no header line with columns {', '.join(REQUIRED)}")


def read_replay_log(path: str | os.PathLike, tolerate: bool = False) -> Recording:
    """Read a replay-log CSV. Strict by default (first bad row is a FogmonError naming
    file, line and column); ``tolerate=True`` skips bad rows and counts them in
    ``Recording.skipped_rows``."""
    path = os.fspath(path)
    name = os.path.basename(path)
    try:
        with open(path, "r", encoding="utf-8", errors="strict") as fh:
            text = fh.read()
    except FileNotFoundError:
        raise FogmonError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise FogmonError(f"{path}: is a directory, not a replay log") from None
    except UnicodeDecodeError as e:
        raise FogmonError(f"{path}: not a text replay log (byte {e.start} is not UTF-8)") from None
    except OSError as e:
        raise FogmonError(f"{path}: cannot read: {e.strerror}") from None
    lines = text.splitlines()
    meta, cols, hline = _parse_header(((i + 1, l) for i, l in enumerate(lines)), name)
    body = lines[hline:]
    data = None
    if not tolerate:
        data = _fast_parse(body, len(cols))
    if data is None:
        data, skipped = _slow_parse(body, cols, hline, name, tolerate)
    else:
        skipped = 0
    ti = cols.index("time_s")
    t = data[:, ti] if len(data) else np.zeros(0)
    if len(t) > 1:
        bad = np.flatnonzero(np.diff(t) <= 0)
        if len(bad):
            if not tolerate:
                # locate the exact line: rerun the slow path which checks ordering.
                _slow_parse(body, cols, hline, name, tolerate=False)
            keep = np.ones(len(t), bool)
            last = -np.inf
            for i in range(len(t)):  # only reached when tolerating out-of-order rows
                if t[i] <= last:
                    keep[i] = False
                else:
                    last = t[i]
            skipped += int((~keep).sum())
            data = data[keep]
    rec = Recording(
        t_s=np.ascontiguousarray(data[:, ti]),
        rate_dph=np.ascontiguousarray(data[:, cols.index("rate_dph")]),
        aux={c: np.ascontiguousarray(data[:, j]) for j, c in enumerate(cols) if c not in REQUIRED},
        meta=meta, path=path, skipped_rows=skipped,
    )
    if len(rec) == 0:
        raise FogmonError(f"{name}: no data rows")
    return rec


def _fast_parse(body: list[str], ncol: int) -> np.ndarray | None:
    """numpy's C parser; None when anything looks wrong (the slow path then names it)."""
    try:
        a = np.loadtxt(io.StringIO("\n".join(body)), delimiter=",", comments="#", ndmin=2, dtype=np.float64)
    except ValueError:
        return None
    if a.size == 0:
        return np.zeros((0, ncol))
    if a.shape[1] != ncol or not np.isfinite(a).all():
        return None
    return a


def _slow_parse(body, cols, hline, name, tolerate):
    rows = []
    skipped = 0
    last_t = -math.inf
    ti = cols.index("time_s")
    for off, line in enumerate(body):
        lineno = hline + 1 + off
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        cells = s.split(",")
        try:
            if len(cells) != len(cols):
                raise FogmonError(f"{name}: line {lineno}: expected {len(cols)} cells "
                                  f"({','.join(cols)}), found {len(cells)}")
            vals = []
            for c, cell in zip(cols, cells):
                try:
                    v = float(cell)
                except ValueError:
                    raise FogmonError(f"{name}: line {lineno}, column {c}: not a number: {cell.strip()!r}") from None
                if not math.isfinite(v):
                    raise FogmonError(f"{name}: line {lineno}, column {c}: {cell.strip()} is not a finite number")
                vals.append(v)
            if vals[ti] <= last_t:
                what = "repeats" if vals[ti] == last_t else "goes backwards"
                raise FogmonError(f"{name}: line {lineno}, column time_s: time {what} "
                                  f"({vals[ti]!r} after {last_t!r})")
        except FogmonError:
            if not tolerate:
                raise
            skipped += 1
            continue
        last_t = vals[ti]
        rows.append(vals)
    return (np.array(rows, dtype=np.float64).reshape(-1, len(cols)), skipped)


def write_replay_log(path: str | os.PathLike, t_s, rate_dph, aux: dict | None = None,
                     meta: dict | None = None) -> None:
    """Write a replay log v1. ``meta`` goes into ``# key: value`` lines (put
    ``sample_rate_hz`` there). Values are written with 12 significant digits."""
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        write_replay_header(fh, list((aux or {}).keys()), meta)
        append_replay_rows(fh, t_s, rate_dph, aux)


def write_replay_header(fh, aux_names: list[str], meta: dict | None = None) -> None:
    """Header of a replay log: magic line, metadata, column names."""
    fh.write(MAGIC + "\n")
    for k, v in (meta or {}).items():
        fh.write(f"# {k}: {v}\n")
    fh.write(",".join(["time_s", "rate_dph", *aux_names]) + "\n")


def append_replay_rows(fh, t_s, rate_dph, aux: dict | None = None) -> None:
    """Append rows (same column order as the header). Non-finite values are not
    allowed in a replay log: drop invalid samples before calling."""
    cols = [np.asarray(t_s, float), np.asarray(rate_dph, float)]
    cols += [np.asarray(a, float) for a in (aux or {}).values()]
    if not len(cols[0]):
        return
    m = np.column_stack(cols)
    fmt = ",".join(["%.12g"] * m.shape[1])
    buf = io.StringIO()
    np.savetxt(buf, m, fmt=fmt)
    fh.write(buf.getvalue())


def recording_from_arrays(t_s, rate_dph, aux=None, meta=None) -> Recording:
    """A Recording from arrays (for notebooks and tests)."""
    return Recording(np.asarray(t_s, float), np.asarray(rate_dph, float),
                     {k: np.asarray(v, float) for k, v in (aux or {}).items()}, dict(meta or {}))
