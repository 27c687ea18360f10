"""The replay log as Parquet: the same columns as the CSV (docs/formats.md, replay log:
``time_s`` s, ``rate_dph`` deg/h or one ``rate_<axis>_dph`` per axis, aux channels),
float64, valid samples only (gaps are time gaps), and the CSV's ``# key: value``
metadata plus units and facts about the source in the file's key-value metadata (key
``fogmon``, a JSON object: ``format``, ``meta`` (the CSV metadata, strings:
``sample_rate_hz``, ``sensor``, ...), ``units`` (column -> unit), and optional
``source`` (what the samples were decoded from), ``sidecar`` (a raw capture's decoder
options) and ``counters`` (the decoder's counts)).

Written in row groups as data arrives (``ParquetLogWriter``); read row group by row group
(``ParquetRows``: memory of one row group, whatever the file size), as one recording
over several files (an archive's pieces and the row-group parts of a piece still being
written, see fogmon.formats.archive)."""
from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Iterator, Sequence

import numpy as np

from fogmon.errors import FogmonError
from fogmon.formats.recording import Recording, rate_axes, rate_columns, sample_rate_from
from fogmon.outputs import write_failed

FORMAT = "fogmon replay log v1 (parquet)"
META_KEY = b"fogmon"
#: units of the columns with a fixed meaning (docs/formats.md, replay log); others: "as recorded"
UNITS = {"time_s": "s", "rate_dph": "deg/h", "temp_c": "deg C", "rot_dps": "deg/s", "vib_g": "g", "depth_m": "m"}
#: rows per row group written by the converter (65.5 s at 1 kHz)
ROW_GROUP_ROWS = 1 << 16


def schema(aux_names: Sequence[str], meta: dict, extra: dict | None = None, axes: tuple[str, ...] = ()):
    """The pyarrow schema of a Parquet replay log with ``aux_names`` and metadata
    ``meta`` (CSV-style, values made strings) plus ``extra`` facts (source, sidecar,
    counters); with ``axes``, one ``rate_<axis>_dph`` column per axis."""
    import pyarrow as pa

    rates = rate_columns(axes)
    cols = ["time_s", *rates, *aux_names]
    info = {"format": FORMAT, "meta": {k: str(v) for k, v in meta.items()},
            "units": {c: "deg/h" if c in rates else UNITS.get(c, "as recorded") for c in cols}, **(extra or {})}
    return pa.schema([(c, pa.float64()) for c in cols], metadata={META_KEY: json.dumps(info).encode()})


def table(sch, t_s, rate_dph, aux: dict):
    """A pyarrow table of rows in schema ``sch`` (a 2-D ``rate_dph``: one column per axis)."""
    import pyarrow as pa

    rate = np.asarray(rate_dph, np.float64)
    rates = [rate] if rate.ndim == 1 else list(rate.T)
    arrays = [np.asarray(t_s, np.float64), *rates]
    arrays += [np.asarray(aux[n], np.float64) for n in sch.names[1 + len(rates):]]
    return pa.Table.from_arrays(arrays, schema=sch)


class ParquetLogWriter:
    """One Parquet replay log written row group by row group: ``write`` buffers rows
    and writes a row group each ``row_group_rows`` rows (``rate_dph`` (n, len(axes)) with
    ``axes``); ``close`` writes the rest and the footer. The file is written as
    ``temp`` (default ``path + '.tmp'``) and renamed on close, so a file named ``path``
    is always complete. A disk error removes what was written and is a FogmonError naming
    the file (as ``name``, e.g. an option, calls it) and the free space."""

    def __init__(self, path: str, aux_names: Sequence[str], meta: dict, extra: dict | None = None,
                 row_group_rows: int = ROW_GROUP_ROWS, axes: tuple[str, ...] = (), temp: str | None = None,
                 name: str = "") -> None:
        import pyarrow.parquet as pq

        self.path, self.name = os.fspath(path), name
        self._file = temp or self.path + ".tmp"
        self.schema = schema(aux_names, meta, extra, axes)
        self.rows = 0
        self._n = int(row_group_rows)
        self._buf: list = []
        self._held = 0
        self._writer = None
        with self._on_error():
            self._writer = pq.ParquetWriter(self._file, self.schema, compression="zstd")

    @contextlib.contextmanager
    def _on_error(self):
        try:
            yield
        except OSError as e:
            self.abort()
            raise write_failed(self.name, self.path, e) from None

    def write(self, t_s, rate_dph, aux: dict) -> None:
        if not len(t_s):
            return
        self._buf.append(table(self.schema, t_s, rate_dph, aux))
        self._held += len(t_s)
        self.rows += len(t_s)
        with self._on_error():
            while self._held >= self._n:
                self._write(self._n)

    def _write(self, n: int) -> None:
        import pyarrow as pa

        t = pa.concat_tables(self._buf)
        assert self._writer is not None, "open until closed"
        self._writer.write_table(t.slice(0, n), row_group_size=n)
        rest = t.slice(n)
        self._buf, self._held = ([rest] if len(rest) else []), len(rest)

    def close(self, counters: dict | None = None) -> None:
        """Write the rest and the footer (with ``counters``, the source's counts, added to
        the ``fogmon`` metadata) and give the file its name."""
        if self._writer is None:
            return
        with self._on_error():
            if self._held:
                self._write(self._held)
            if counters is not None:
                info = json.loads(self.schema.metadata[META_KEY])
                self._writer.add_key_value_metadata({META_KEY.decode(): json.dumps({**info, "counters": counters})})
            self._writer.close()
            self._writer = None
            os.replace(self._file, self.path)

    def abort(self) -> None:
        """Stop without a file (an error while converting); idempotent."""
        if self._writer is not None:
            with contextlib.suppress(OSError):
                self._writer.close()
            self._writer = None
        with contextlib.suppress(OSError):
            os.remove(self._file)


def file_info(pf, path: str) -> tuple[dict, tuple[str, ...]]:
    """The ``fogmon`` metadata of an open ``pq.ParquetFile`` and its axes (() for one
    axis; its columns checked as a CSV header is: one-line error naming the file and
    column otherwise)."""
    md = pf.metadata.metadata or {}      # the file's key-value metadata (the footer's, the latest)
    try:
        info = json.loads(md[META_KEY])
        ok = isinstance(info, dict) and isinstance(info.get("meta", {}), dict)
    except (KeyError, ValueError):
        ok = False
    if not ok:
        info = {"meta": {}}
    names = pf.schema_arrow.names
    return info, rate_axes(names, path, ", ".join(names))


class ParquetRows:
    """A Parquet replay log (one file, or several in order: pieces of one recording) as
    the rows a ``ReplayLogSource`` (fogmon.sources.files.replay_log) takes: ``meta``,
    ``axes``, ``aux_names``, ``sample_rate_hz``, ``name`` and ``chunks()`` yielding one
    row group at a time (checked: finite values, time strictly increasing; a bad row is
    a one-line error naming file, row and column, or skipped and counted with
    ``tolerate``)."""

    def __init__(self, paths: str | os.PathLike | Sequence[str], tolerate: bool = False) -> None:
        self.paths = [os.fspath(paths)] if isinstance(paths, (str, os.PathLike)) else [os.fspath(p) for p in paths]
        self.tolerate = tolerate
        first = os.path.basename(self.paths[0])
        self.name = first if len(self.paths) == 1 else f"{first} .. {os.path.basename(self.paths[-1])} " \
                                                       f"({len(self.paths)} files)"
        self.n_rows = 0
        columns: list[str] | None = None
        for p in self.paths:
            pf = _open(p)
            info, axes = file_info(pf, p)
            if columns is None:
                columns = pf.schema_arrow.names
                self.axes = axes
                self.meta = dict(info.get("meta", {}))
                self.info = info          # the first file's metadata: units, source, sidecar facts
            elif pf.schema_arrow.names != columns:
                raise FogmonError(f"{p}: columns {pf.schema_arrow.names} differ from {self.paths[0]} ({columns}): "
                                  f"not parts of one recording")
            elif info.get("meta", {}).get("sample_rate_hz") != self.meta.get("sample_rate_hz"):
                raise FogmonError(f"{p}: sample_rate_hz differs from {self.paths[0]}: not parts of one recording")
            self.n_rows += pf.metadata.num_rows
        assert columns is not None  # self.paths is never empty
        self.columns: list[str] = columns
        self.rate_names = rate_columns(self.axes)
        self.aux_names = [c for c in columns if c != "time_s" and c not in self.rate_names]
        self.sample_rate_hz = sample_rate_from(self.meta, self._first_times(), self.name) \
            if "sample_rate_hz" not in self.meta else sample_rate_from(self.meta, np.zeros(0), self.name)

    def _first_times(self) -> np.ndarray:
        for rows in self.chunks():
            if len(rows):
                return rows.t_s
        return np.zeros(0)

    def chunks(self) -> Iterator[_Rows]:
        last_t = -math.inf
        for p in self.paths:
            pf = _open(p)
            row0 = 0
            for g in range(pf.metadata.num_row_groups):
                try:
                    tbl = pf.read_row_group(g)
                except Exception as e:  # pyarrow raises several types for a damaged file
                    raise FogmonError(f"{p}: row group {g + 1} unreadable: {e}") from None
                cols = {c: tbl.column(c).to_numpy(zero_copy_only=False).astype(np.float64, copy=False)
                        for c in self.columns}
                rows, skipped = self._checked(p, row0, cols, last_t)
                row0 += tbl.num_rows
                if len(rows):
                    last_t = float(rows.t_s[-1])
                rows.skipped = skipped
                yield rows

    def _checked(self, path: str, row0: int, cols: dict, last_t: float) -> tuple[_Rows, int]:
        t = cols["time_s"]
        bad = np.zeros(len(t), bool)
        for c, a in cols.items():
            nf = ~np.isfinite(a)
            if nf.any() and not self.tolerate:
                i = int(np.argmax(nf))
                raise FogmonError(f"{path}: row {row0 + i + 1}, column {c}: {a[i]} is not a finite number")
            bad |= nf
        keep = ~bad
        tk = t[keep]
        order_bad = np.diff(np.concatenate([[last_t], tk])) <= 0
        if order_bad.any():
            j = int(np.argmax(order_bad))
            i = int(np.flatnonzero(keep)[j])
            prev = last_t if j == 0 else tk[j - 1]
            what = "repeats" if tk[j] == prev else "goes backwards"
            raise FogmonError(f"{path}: row {row0 + i + 1}, column time_s: time {what} ({tk[j]!r} after {prev!r})")
        rate = np.column_stack([cols[c] for c in self.rate_names]) if self.axes else cols["rate_dph"]
        rows = _Rows(tk, rate[keep], {c: cols[c][keep] for c in self.aux_names})
        return rows, int(bad.sum())


class _Rows:
    """One row group's rows (the shape of fogmon.formats.replay_log.Rows; ``line_of`` None: a
    Parquet file has rows, not lines, and errors name the time value)."""

    line_of = None

    def __init__(self, t_s, rate_dph, aux) -> None:
        self.t_s, self.rate_dph, self.aux, self.skipped = t_s, rate_dph, aux, 0

    def __len__(self) -> int:
        return len(self.t_s)


def _open(path: str):
    import pyarrow.parquet as pq

    try:
        return pq.ParquetFile(path)
    except FileNotFoundError:
        raise FogmonError(f"{path}: no such file") from None
    except OSError as e:
        raise FogmonError(f"{path}: cannot read: {e}") from None
    except Exception as e:  # ArrowInvalid: not a Parquet file / no footer
        raise FogmonError(f"{path}: not a readable Parquet file ({e})") from None


def read_parquet_log(paths: str | os.PathLike | Sequence[str], tolerate: bool = False) -> Recording:
    """A whole Parquet replay log in memory (the batch commands: explain, sim --like, ...)."""
    reader = ParquetRows(paths, tolerate=tolerate)
    parts: dict[str, list[np.ndarray]] = {c: [] for c in ("time_s", "rate_dph", *reader.aux_names)}
    skipped = 0
    for rows in reader.chunks():
        parts["time_s"].append(rows.t_s)
        parts["rate_dph"].append(rows.rate_dph)
        for c in reader.aux_names:
            parts[c].append(rows.aux[c])
        skipped += rows.skipped
    if not sum(len(a) for a in parts["time_s"]):
        raise FogmonError(f"{reader.name}: no data rows")
    whole = {c: np.concatenate(v) for c, v in parts.items()}
    return Recording(whole.pop("time_s"), whole.pop("rate_dph"), whole, reader.meta, reader.paths[0], skipped,
                     reader.axes)
