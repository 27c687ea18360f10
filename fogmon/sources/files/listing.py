"""What a file holds, for ``fogmon info`` and for errors that would otherwise cut a list:
one ``Entry`` per topic, channel, signal or column (name, type, count, mean rate from its
time stamps, span, unit); and ``quiet()``, which keeps third-party readers' own output
(prints, log records, warnings) off the user's terminal."""
from __future__ import annotations

import contextlib
import gc
import io
import logging
import math
import sys
import traceback
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from fogmon.errors import FogmonError


@dataclass(frozen=True)
class Entry:
    """One topic / channel / signal / column of a file: ``count`` samples over ``span_s``
    (first to last time stamp, s) at ``rate_hz`` = (count - 1) / span (NaN when fewer
    than two stamps or no time), ``unit`` as the file states it ("" when none)."""

    name: str
    type: str
    count: int
    rate_hz: float
    span_s: float
    unit: str = ""


def stamped_entry(name: str, type: str, t_s, unit: str = "") -> Entry:
    """An Entry from the time stamps ``t_s`` (s) of a series."""
    t = np.asarray(t_s, dtype=np.float64)
    t = t[np.isfinite(t)]
    span = float(t.max() - t.min()) if len(t) > 1 else math.nan
    rate = (len(t) - 1) / span if len(t) > 1 and span > 0 else math.nan
    return Entry(name, type, int(np.size(t_s)), rate, span, unit or "")


HEADER = ("name", "type", "count", "rate_hz", "span_s", "unit")


def format_entries(entries: Sequence[Entry]) -> list[str]:
    """The lines ``fogmon info`` prints: a header, then one line per entry, columns
    separated by two spaces and aligned; rate in Hz to 6 digits, span in s."""
    rows = [HEADER] + [(e.name, e.type, str(e.count), "-" if math.isnan(e.rate_hz) else f"{e.rate_hz:.6g}",
                        "-" if math.isnan(e.span_s) else f"{e.span_s:.6g}", e.unit or "-") for e in entries]
    width = [max(len(r[i]) for r in rows) for i in range(len(HEADER))]
    return ["  ".join(c.ljust(w) if i < 2 or i == 5 else c.rjust(w)
                      for i, (c, w) in enumerate(zip(r, width, strict=True))).rstrip() for r in rows]


def point_to_info(path: str, what: str, names: Sequence[str], shown: int = 12) -> str:
    """``names`` for an error message: all of them when few, else how many and the
    command that lists them (never a cut list)."""
    if len(names) <= shown:
        return ", ".join(names) or "none"
    return f"{len(names)} {what}, listed by: fogmon info {path}"


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """Third-party readers' stray output off the terminal while the block runs: their
    prints to stdout/stderr, their log records and their Python warnings are dropped
    (a FogmonWarning must be issued outside the block)."""
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()), \
                contextlib.redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore")
            yield
    finally:
        logging.disable(previous)
        sys.stdout.flush()


@contextlib.contextmanager
def reading(what: str, silent: bool = True) -> Iterator[None]:
    """A third-party read, ``quiet()`` (unless not ``silent``: fogmon's own code that may
    warn): any exception other than a FogmonError becomes a one-line FogmonError ``what
    (ExceptionType: its first line)``, raised once the library's objects are released
    (so that their clean-up output is dropped too)."""
    why = None
    with quiet() if silent else contextlib.nullcontext():
        try:
            yield
        except FogmonError:
            raise
        except Exception as e:  # any library error on a corrupt file: one line, never a traceback
            text = (str(e).splitlines() or [""])[0][:200]
            why = f"{type(e).__name__}{': ' + text if text else ''}"
            traceback.clear_frames(e.__traceback__)   # the library's half-built objects released here, inside
            gc.collect()                              # quiet(): their clean-up errors are not printed
    if why is not None:
        raise FogmonError(f"{what} ({why})")


class BoundedFile(io.RawIOBase):
    """A file read through a budget: reading more than ``times`` times its size (a reader
    looping on a corrupt file: seeking back to the same bytes forever) raises OSError, so
    that every reader given it ends in bounded time."""

    def __init__(self, path: str, times: int = 8) -> None:
        super().__init__()
        self._fh = open(path, "rb")  # noqa: SIM115 (closed by close())
        self._fh.seek(0, io.SEEK_END)
        self._budget = times * max(self._fh.tell(), 1 << 16)
        self._fh.seek(0)
        self.name = path

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        n = self._fh.readinto(b)
        self._budget -= max(n or 0, 1)
        if self._budget < 0:
            raise OSError(f"{self.name}: the reader went over the file again and again (a corrupt file)")
        return n

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        return self._fh.seek(offset, whence)

    def tell(self) -> int:
        return self._fh.tell()

    def close(self) -> None:
        self._fh.close()
        super().close()


def bounded(path: str, times: int = 8) -> io.BufferedReader:
    """``path`` opened for reading through a BoundedFile (a buffered binary file)."""
    return io.BufferedReader(BoundedFile(path, times))
