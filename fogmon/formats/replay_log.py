"""Replay log v1 (docs/formats.md): the CSV recording format every command reads,
and `fogmon monitor`/`fogmon sim` write. Parsing is strict: a bad cell, NaN/inf, time
going backwards or repeating is a one-line error naming file, line and column, unless
the caller asks to tolerate bad rows, in which case they are skipped and counted.

``ReplayLogReader`` reads a log in chunks of whole lines (bounded memory, the same rows
however the chunks fall); ``read_replay_log`` collects them into a ``Recording`` for the
batch commands; ``write_replay_log`` (or ``write_replay_header`` and ``append_replay_rows``)
writes one. Lines are limited to MAX_LINE_BYTES. The recording in memory and the rate
columns' names are fogmon.formats.recording's."""
from __future__ import annotations

import functools
import io
import math
import os
import warnings
from collections.abc import Generator
from dataclasses import dataclass

import numpy as np

from fogmon.errors import FogmonError
from fogmon.formats.recording import RATE_SAMPLES, Recording, rate_axes, rate_columns, sample_rate_from

MAGIC = "# fogmon replay log v1"
REQUIRED = ("time_s", "rate_dph")
#: bytes of whole lines parsed at a time (reading memory is a small multiple of this)
CHUNK_BYTES = 1 << 20
#: the longest line a replay log may have, in bytes (a file without newlines is not a log)
MAX_LINE_BYTES = 1 << 20
_BOM = b"\xef\xbb\xbf"
#: a cell quoted in an error message is cut to this many characters
_CELL_SHOWN = 40


@dataclass
class Rows:
    """Rows of one chunk of a replay log, in file order: ``t_s`` (s), ``rate_dph``
    (deg/h; one column per axis of a multi-axis log), aux channels by column name;
    ``skipped`` bad rows left out (tolerant reading only). ``line_of(i)`` is the file
    line of row ``i`` (error messages)."""

    t_s: np.ndarray
    rate_dph: np.ndarray
    aux: dict[str, np.ndarray]
    skipped: int
    first_line: int
    _text: bytes = b""
    _last_t: float = -math.inf
    _reader: ReplayLogReader | None = None

    def __len__(self) -> int:
        return len(self.t_s)

    def line_of(self, i: int) -> int:
        assert self._reader is not None, "Rows made by ReplayLogReader.chunks carry their reader"
        _, lines, _ = self._reader._parse_slow(self._text, self.first_line, self._last_t)
        return int(lines[i])


class ReplayLogReader:
    """A replay log read in chunks of whole lines: memory independent of the file size.
    Opening reads the header (``meta``, ``columns``, ``axes``: the axis names of
    ``rate_<axis>_dph`` columns, () for a one-axis log); ``chunks()`` parses the body from
    the start each time it is called. Strict unless ``tolerate`` (bad rows skipped and
    counted in ``Rows.skipped``). A UTF-8 byte-order mark and CRLF line ends are
    accepted; a line longer than ``max_line_bytes`` is an error naming it."""

    def __init__(self, path: str | os.PathLike, tolerate: bool = False, chunk_bytes: int = CHUNK_BYTES,
                 max_line_bytes: int = MAX_LINE_BYTES) -> None:
        self.path = os.fspath(path)
        self.name = os.path.basename(self.path)
        self.tolerate = tolerate
        self._chunk, self._max_line = max(int(chunk_bytes), 16), int(max_line_bytes)
        self.meta, self.columns, self._body = self._read_header()
        self.rate_names = rate_columns(self.axes)
        self.aux_names = [c for c in self.columns if c != "time_s" and c not in self.rate_names]

    @functools.cached_property
    def sample_rate_hz(self) -> float:
        """Nominal sample rate (Hz, ``sample_rate_from``): from the metadata, or from the
        first RATE_SAMPLES samples (reading only those)."""
        if "sample_rate_hz" in self.meta:
            return sample_rate_from(self.meta, np.zeros(0), self.name)
        first, n = [], 0
        chunks = self.chunks()
        for rows in chunks:
            first.append(rows.t_s[:RATE_SAMPLES + 1 - n].copy())
            n += len(first[-1])
            if n > RATE_SAMPLES:
                break
        chunks.close()
        return sample_rate_from({}, np.concatenate(first) if first else np.zeros(0), self.name)

    def _open(self):
        try:
            return open(self.path, "rb")
        except FileNotFoundError:
            raise FogmonError(f"{self.path}: no such file") from None
        except IsADirectoryError:
            raise FogmonError(f"{self.path}: is a directory, not a replay log") from None
        except OSError as e:
            raise FogmonError(f"{self.path}: cannot read: {e.strerror}") from None

    def _line_chunks(self, offset: int, lineno: int):
        """(byte offset, number of the first line, whole lines as bytes) from ``offset``,
        about ``chunk_bytes`` at a time; the last chunk may lack its newline."""
        with self._open() as fh:
            fh.seek(offset)
            pending = b""
            while True:
                try:
                    data = fh.read(self._chunk)
                except OSError as e:
                    raise FogmonError(f"{self.path}: cannot read: {e.strerror}") from None
                if offset == 0 and not pending and data.startswith(_BOM):
                    data, offset = data[len(_BOM):], len(_BOM)
                buf = pending + data if pending else data
                cut = len(buf) if not data else buf.rfind(b"\n") + 1
                block, pending = buf[:cut], buf[cut:]
                if len(pending) > self._max_line:
                    self._too_long(lineno + block.count(b"\n"))
                if block:
                    self._check_line_lengths(block, lineno)
                    yield offset, lineno, block
                    offset += len(block)
                    lineno += block.count(b"\n")
                if not data:
                    return

    def _check_line_lengths(self, block: bytes, lineno: int) -> None:
        if len(block) <= self._max_line:
            return
        ends = np.flatnonzero(np.frombuffer(block, np.uint8) == 10)
        lengths = np.diff(np.concatenate([[-1], ends, [len(block) - 1]]))
        if lengths.max() > self._max_line + 1:
            self._too_long(lineno + int(np.argmax(lengths > self._max_line + 1)))

    def _too_long(self, lineno: int):
        raise FogmonError(f"{self.name}: line {lineno} longer than {self._max_line} bytes (not a replay log?)")

    def _text(self, block: bytes, lineno: int) -> str:
        try:
            return block.decode("utf-8")
        except UnicodeDecodeError as e:
            line, col = lineno + block.count(b"\n", 0, e.start), e.start - block.rfind(b"\n", 0, e.start)
            raise FogmonError(f"{self.name}: line {line}: not UTF-8 text (byte {col} of the line)") from None

    def _read_header(self) -> tuple[dict[str, str], list[str], tuple[int, int]]:
        """(meta, columns, (byte offset, line number) of the first body line)."""
        meta: dict[str, str] = {}
        for offset, lineno, block in self._line_chunks(0, 1):
            pos = 0
            for i, line in enumerate(self._text(block, lineno).split("\n")):
                raw_len = len(line.encode("utf-8")) + 1
                s = line.strip()
                if s.startswith("#"):
                    body = s[1:].strip()
                    if ":" in body and not body.lower().startswith("fogmon replay log"):
                        k, v = body.split(":", 1)
                        if k.strip() and " " not in k.strip():
                            meta[k.strip()] = v.strip()
                elif s:
                    return meta, self._columns(s, lineno + i), (offset + pos + raw_len, lineno + i + 1)
                pos += raw_len
        raise FogmonError(f"{self.name}: no header line with columns {', '.join(REQUIRED)}")

    def _columns(self, s: str, lineno: int) -> list[str]:
        cols = [c.strip() for c in s.split(",")]
        shown = ", ".join(cols) if len(s) <= 200 else s[:200] + "..."
        self.axes = rate_axes(cols, f"{self.name}: line {lineno}", shown)
        seen = set()
        for c in cols:
            if not c:
                raise FogmonError(f"{self.name}: line {lineno}: empty column name in header")
            if c in seen:
                raise FogmonError(f"{self.name}: line {lineno}: duplicated column {c!r}")
            seen.add(c)
        return cols

    def chunks(self) -> Generator[Rows, None, None]:
        """The body's rows chunk by chunk, checked: numbers, finite, time strictly
        increasing across chunks. FogmonError naming file, line and column at the first
        bad row (unless tolerating)."""
        last_t = -math.inf
        cols = self.columns
        ti = cols.index("time_s")
        ri = [cols.index(c) for c in self.rate_names] if self.axes else cols.index("rate_dph")
        for _, lineno, block in self._line_chunks(*self._body):
            data = _parse_fast(block, len(cols))
            skipped = 0
            if data is None or (len(data) and (data[0, ti] <= last_t or np.any(np.diff(data[:, ti]) <= 0))):
                data, _, skipped = self._parse_slow(block, lineno, last_t)
            rows = Rows(data[:, ti], data[:, ri], {c: data[:, j] for j, c in enumerate(cols) if c in self.aux_names},
                        skipped, lineno, block, last_t, self)
            if len(data):
                last_t = float(data[-1, ti])
            yield rows

    def _parse_slow(self, block: bytes, lineno: int, last_t: float):
        """Row by row: (rows, their line numbers, rows skipped); raises at the first bad
        row unless tolerating."""
        cols, name = self.columns, self.name
        ti = cols.index("time_s")
        rows, lines = [], []
        skipped = 0
        for off, line in enumerate(self._text(block, lineno).split("\n")):
            at = lineno + off
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            cells = s.split(",")
            try:
                if len(cells) != len(cols):
                    raise FogmonError(f"{name}: line {at}: expected {len(cols)} cells "
                                      f"({','.join(cols)}), found {len(cells)}")
                vals = []
                for c, cell in zip(cols, cells, strict=True):
                    try:
                        v = float(cell)
                    except ValueError:
                        raise FogmonError(f"{name}: line {at}, column {c}: not a number: {_shown(cell)}") from None
                    if not math.isfinite(v):
                        raise FogmonError(f"{name}: line {at}, column {c}: {cell.strip()} is not a finite number")
                    vals.append(v)
                if vals[ti] <= last_t:
                    what = "repeats" if vals[ti] == last_t else "goes backwards"
                    raise FogmonError(f"{name}: line {at}, column time_s: time {what} "
                                      f"({vals[ti]!r} after {last_t!r})")
            except FogmonError:
                if not self.tolerate:
                    raise
                skipped += 1
                continue
            last_t = vals[ti]
            rows.append(vals)
            lines.append(at)
        return np.array(rows, dtype=np.float64).reshape(-1, len(cols)), np.array(lines, dtype=np.int64), skipped


def _shown(cell: str) -> str:
    """A cell for an error message: repr, cut to _CELL_SHOWN characters."""
    c = cell.strip()
    return repr(c) if len(c) <= _CELL_SHOWN else repr(c[:_CELL_SHOWN]) + f"... ({len(c)} characters)"


def _float64_column(col) -> np.ndarray:
    """A float64 pyarrow ChunkedArray as a numpy array, read from its chunks' data
    buffers (pyarrow's to_numpy imports pandas: ~0.3 CPU s of start-up); ValueError when
    it holds nulls."""
    if col.null_count:
        raise ValueError("null cells")
    parts = [np.frombuffer(c.buffers()[1], dtype=np.float64, count=len(c), offset=8 * c.offset) for c in col.chunks]
    return np.concatenate(parts) if parts else np.zeros(0)


def _parse_fast(block: bytes, ncol: int) -> np.ndarray | None:
    """Rows of ``block`` by a C parser (pyarrow, numpy's loadtxt where there are comment
    lines); None when anything looks wrong (the row-by-row parser then names it)."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    if not block.strip():
        return np.zeros((0, ncol))
    a = None
    if b"#" not in block:
        names = [f"c{j}" for j in range(ncol)]
        try:
            tbl = pacsv.read_csv(pa.py_buffer(block),
                                 read_options=pacsv.ReadOptions(column_names=names, use_threads=False),
                                 parse_options=pacsv.ParseOptions(quote_char=False),
                                 convert_options=pacsv.ConvertOptions(column_types=dict.fromkeys(names, pa.float64()),
                                                                      null_values=[], strings_can_be_null=False))
            a = np.column_stack([_float64_column(tbl.column(j)) for j in range(ncol)])
        except (pa.ArrowInvalid, ValueError):
            a = None
    if a is None:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                a = np.loadtxt(io.StringIO(block.decode("utf-8")), delimiter=",", comments="#", ndmin=2,
                               dtype=np.float64)
        except ValueError:  # UnicodeDecodeError included
            return None
    if a.size == 0:
        return np.zeros((0, ncol))
    if a.shape[1] != ncol or not np.isfinite(a).all():
        return None
    return a


def read_replay_log(path: str | os.PathLike, tolerate: bool = False) -> Recording:
    """Read a whole replay-log CSV into memory (the batch commands; ``fogmon replay``
    streams it with ReplayLogReader). Strict by default (first bad row is a FogmonError
    naming file, line and column); ``tolerate=True`` skips bad rows and counts them in
    ``Recording.skipped_rows``. A ``*.parquet`` path is read as a Parquet replay log
    (fogmon.formats.parquet_log)."""
    if os.fspath(path).lower().endswith(".parquet"):
        from fogmon.formats.parquet_log import read_parquet_log
        return read_parquet_log(path, tolerate=tolerate)
    reader = ReplayLogReader(path, tolerate=tolerate)
    cols: dict[str, list[np.ndarray]] = {c: [] for c in ("time_s", "rate_dph", *reader.aux_names)}
    skipped = 0
    for rows in reader.chunks():  # keep the values only, not each chunk's text
        for c, a in (("time_s", rows.t_s), ("rate_dph", rows.rate_dph), *rows.aux.items()):
            cols[c].append(a)
        skipped += rows.skipped
    if not sum(len(a) for a in cols["time_s"]):
        raise FogmonError(f"{reader.name}: no data rows")
    whole = {c: np.concatenate(v) for c, v in cols.items()}
    return Recording(t_s=whole.pop("time_s"), rate_dph=whole.pop("rate_dph"), aux=whole, meta=reader.meta,
                     path=reader.path, skipped_rows=skipped, axes=reader.axes,
                     line_of=functools.partial(_line_of_row, reader))


def _line_of_row(reader: ReplayLogReader, i: int) -> int:
    """The file line of row ``i`` of the log ``reader`` reads (for an error message: the
    chunks' text is not kept, so the file is read again up to that row)."""
    seen = 0
    for rows in reader.chunks():
        if i < seen + len(rows):
            return rows.line_of(i - seen)
        seen += len(rows)
    raise IndexError(f"{reader.name}: no row {i}")


def write_replay_log(path: str | os.PathLike, t_s, rate_dph, aux: dict | None = None,
                     meta: dict | None = None, axes: tuple[str, ...] = ()) -> None:
    """Write a replay log v1. ``meta`` goes into ``# key: value`` lines (put
    ``sample_rate_hz`` there). Values are written with 12 significant digits. With
    ``axes``, ``rate_dph`` is (n, len(axes)), written as ``rate_<axis>_dph`` columns."""
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        write_replay_header(fh, list((aux or {}).keys()), meta, axes)
        append_replay_rows(fh, t_s, rate_dph, aux)


def write_replay_header(fh, aux_names: list[str], meta: dict | None = None, axes: tuple[str, ...] = ()) -> None:
    """Header of a replay log: magic line, metadata, column names."""
    fh.write(MAGIC + "\n")
    for k, v in (meta or {}).items():
        fh.write(f"# {k}: {v}\n")
    fh.write(",".join(["time_s", *rate_columns(axes), *aux_names]) + "\n")


def append_replay_rows(fh, t_s, rate_dph, aux: dict | None = None) -> None:
    """Append rows (same column order as the header; a 2-D ``rate_dph`` gives one
    column per axis). Non-finite values are not allowed in a replay log: drop invalid
    samples before calling."""
    cols = [np.asarray(t_s, float), np.asarray(rate_dph, float)]
    cols += [np.asarray(a, float) for a in (aux or {}).values()]
    if not len(cols[0]):
        return
    m = np.column_stack(cols)
    row = ",".join(["%.12g"] * m.shape[1]) + "\n"
    fh.write((row * len(m)) % tuple(m.ravel().tolist()))   # one C-level format: what np.savetxt writes


