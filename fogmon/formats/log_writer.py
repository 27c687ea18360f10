"""A replay log written block by block, in the format its name asks for: ``.csv``
(fogmon.formats.replay_log) or ``.parquet`` (fogmon.formats.parquet_log). What `fogmon
sim` and `fogmon convert` write.

The file is written under a temporary name in the target's folder and renamed when
closed, so the target is a complete log or untouched: ``abort`` (and any error) removes
what was written. A replay log holds only finite numbers: a non-finite value is a
FogmonError naming the column and the time. A disk error (full, quota, I/O, a file-size
limit) is a FogmonError naming the file and the free space (fogmon.outputs.write_failed).
``bytes_per_row`` is measured on what was written so far (CSV; Parquet: uncompressed
float64, an upper bound), for checking the free space before long work."""
from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Sequence

import numpy as np

from fogmon.errors import FogmonError
from fogmon.formats.replay_log import append_replay_rows, rate_columns, write_replay_header
from fogmon.outputs import temp_path, write_failed

#: the suffixes a replay log is written as
LOG_SUFFIXES = (".csv", ".parquet")


def check_log_suffix(name: str, path: str) -> str:
    """The suffix of ``path`` (.csv or .parquet), or FogmonError naming ``name``."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in LOG_SUFFIXES:
        raise FogmonError(f"{name} {path}: name it .csv (replay log) or .parquet (Parquet replay log); "
                          f"fogmon writes no other format")
    return ext


class LogWriter:
    """Replay log ``path`` (``name``: how messages name it) with columns time_s, the
    rate (one column per axis of ``axes``) and ``aux_names``, metadata ``meta`` (and,
    Parquet only, ``extra`` in its ``fogmon`` metadata). ``write`` appends rows,
    ``close`` completes the file, ``abort`` removes it. As a context manager: closed at
    the end of the block (unless closed in it, e.g. with counters), aborted when the block
    raises: complete or not written."""

    def __init__(self, path: str, aux_names: Sequence[str], meta: dict, axes: tuple[str, ...] = (),
                 extra: dict | None = None, name: str = "") -> None:
        self.path, self.name = os.fspath(path), name
        self.columns = ["time_s", *rate_columns(axes), *aux_names]
        self.rows = 0
        self.bytes = 0
        self._tmp = temp_path(self.path)
        self._parquet = check_log_suffix(name, self.path) == ".parquet"
        self._fh: io.TextIOBase | None = None
        self._pq = None
        try:
            if self._parquet:
                from fogmon.formats.parquet_log import ParquetLogWriter
                self._pq = ParquetLogWriter(os.path.realpath(self.path), aux_names, meta, extra, axes=axes,
                                            temp=self._tmp, name=name)
            else:
                self._fh = open(self._tmp, "w", encoding="utf-8", newline="\n")  # noqa: SIM115 - closed in close/abort
                write_replay_header(self._fh, list(aux_names), meta, axes)
        except OSError as e:
            self.abort()
            raise write_failed(name, self.path, e) from None

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, kind, value, traceback) -> None:
        if kind is None:
            self.close()
        else:
            self.abort()

    @property
    def bytes_per_row(self) -> float:
        """Bytes per row written so far (nan before the first row)."""
        return self.bytes / self.rows if self.rows else float("nan")

    def write(self, t_s, rate_dph, aux: dict) -> None:
        """Append rows (``rate_dph`` (n, len(axes)) with axes)."""
        t_s = np.asarray(t_s, float)
        if not len(t_s):
            return
        self._check_finite(t_s, rate_dph, aux)
        try:
            if self._pq is not None:
                self._pq.write(t_s, rate_dph, aux)
                self.bytes += 8 * len(self.columns) * len(t_s)
            else:
                buf = io.StringIO()
                append_replay_rows(buf, t_s, rate_dph, aux)
                text = buf.getvalue()
                assert self._fh is not None, "open until closed"
                self._fh.write(text)
                self.bytes += len(text)
        except OSError as e:
            self.abort()
            raise write_failed(self.name, self.path, e) from None
        self.rows += len(t_s)

    def _check_finite(self, t_s: np.ndarray, rate_dph, aux: dict) -> None:
        cols = [t_s, np.asarray(rate_dph, float).reshape(len(t_s), -1), *(np.asarray(a, float) for a in aux.values())]
        m = np.column_stack(cols)
        bad = ~np.isfinite(m)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            self.abort()
            raise FogmonError(f"{self.name + ' ' if self.name else ''}{self.path}: {self.columns[j]} is {m[i, j]} at "
                              f"time_s {t_s[i]:.6g} s: a replay log holds only finite numbers (nothing written)")

    def close(self, counters: dict | None = None) -> None:
        """Complete the file and give it its name (Parquet: ``counters`` into its metadata)."""
        try:
            if self._pq is not None:
                self._pq.close(counters)     # renames it
            elif self._fh is not None:
                self._fh.close()
                os.replace(self._tmp, os.path.realpath(self.path))
        except OSError as e:
            self.abort()
            raise write_failed(self.name, self.path, e) from None
        self._fh = self._pq = None

    def abort(self) -> None:
        """Stop and remove what was written (idempotent)."""
        if self._pq is not None:
            self._pq.abort()
        if self._fh is not None:
            with contextlib.suppress(OSError):
                self._fh.close()
        self._fh = self._pq = None
        with contextlib.suppress(OSError):
            os.remove(self._tmp)
