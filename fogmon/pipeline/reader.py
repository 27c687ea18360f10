"""A source's blocks read in a thread through a bounded queue (``_ThreadedBlocks``): a
source that can wait is held back while the queue is full (back-pressure); a live device
never is: the blocks it reads while the pipeline is too far behind are dropped, counted
and come out as invalid placeholders on the same grid with a ``dropped`` event.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from fogmon.block import Block, Event
from fogmon.sources.base import Source

#: Samples read but not yet processed that a live run or an endless simulation may hold
#: (2**20: 17 min at 1 kHz); beyond it a simulation waits and a live device's blocks are
#: dropped, counted and reported.
QUEUE_MAX_SAMPLES = 2**20
#: Placeholders for dropped samples come in blocks of at most this many samples.
PLACEHOLDER_BLOCK = 2**16
#: Events of dropped blocks kept (the rest are counted in the ``dropped`` event).
DROPPED_EVENTS_KEPT = 1000


@dataclass
class _Dropped:
    """Consecutive blocks of a live source dropped from the reader's queue: their span on
    the sample grid (``n`` samples from ``t0_s``) and the first of their events."""

    t0_s: float
    n: int
    blocks: int
    events: list[Event]
    events_left_out: int = 0


class _ThreadedBlocks:
    """Iterate a source's blocks in a reader thread through a queue holding at most
    ``max_samples`` samples (a block alone may be longer), so DAVAR, fits and Rerun never
    keep a device unread and memory stays bounded.

    A source that can wait (a simulation, a file) is held back while the queue is full:
    back-pressure. A live device (``source.live``, ``wait=False``) never is, since an OS serial
    buffer holds ~0.1 s of a 1 kHz KVH: when the pipeline is more than ``max_samples``
    behind, the blocks read meanwhile are dropped, counted (``blocks_dropped``,
    ``samples_dropped`` in ``counters``) and come out as invalid placeholders on the
    same grid with a ``dropped`` event, so the time base holds and nothing is lost
    silently (the raw capture of an archive, written by the device thread, keeps them).
    ``backlog()`` after ``source.close()`` takes what is left once the reader is done."""

    _DONE = object()

    def __init__(self, source: Source, max_samples: int = QUEUE_MAX_SAMPLES, wait: bool | None = None):
        self._source = source
        self.max_samples = max_samples
        self.wait = not source.live if wait is None else wait
        self.counters = {} if self.wait else {"blocks_dropped": 0, "samples_dropped": 0}
        self._aux_names: tuple[str, ...] = ()  # of the blocks read, for placeholders
        self._axes: tuple[str, ...] = ()
        self.held_back = 0  # times the reader waited for room (back-pressure)
        self._items: deque = deque()
        self._n = 0  # samples in the queue
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._read, name="fogmon-source-reader", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            for b in self._source.blocks():
                if not self._put(b):
                    return
        except BaseException as e:  # handed to the consumer thread
            self._append(e, 0)
        finally:
            self._append(self._DONE, 0)

    def _put(self, b: Block) -> bool:
        """Queue ``b``, waiting for room or dropping it; False once a source that waits is
        closed (nothing more of it is needed). A live device's blocks are queued even after
        the stop: they were read and archived, so ``backlog()`` hands them on to be counted."""
        with self._cond:
            if self._n and self._n + len(b) > self.max_samples:
                if not self.wait:
                    self._drop(b)
                    return True
                self.held_back += 1
                self._cond.notify_all()
                while self._n and self._n + len(b) > self.max_samples and not self._closed:
                    self._cond.wait()
            if self._closed and self.wait:
                return False
            self._aux_names, self._axes = tuple(b.aux), b.axes
        self._append(b, len(b))
        return True

    def _append(self, item, n: int) -> None:
        with self._cond:
            self._items.append(item)
            self._n += n
            self._cond.notify_all()

    def _drop(self, b: Block) -> None:
        self.counters["blocks_dropped"] += 1
        self.counters["samples_dropped"] += len(b)
        rate = float(self._source.sample_rate_hz)
        last = self._items[-1] if self._items else None
        if not (isinstance(last, _Dropped) and abs(last.t0_s + last.n / rate - float(b.t_s[0])) < 0.5 / rate):
            last = _Dropped(float(b.t_s[0]), 0, 0, [])
            self._items.append(last)
        last.n += len(b)
        last.blocks += 1
        room = DROPPED_EVENTS_KEPT - len(last.events)
        last.events += b.events[:room]
        last.events_left_out += max(len(b.events) - room, 0)
        self._cond.notify_all()

    def __iter__(self):
        while True:
            with self._cond:
                while not self._items:
                    self._cond.wait(0.25)  # wakes for Ctrl-C in the main thread
                item = self._items.popleft()
                if isinstance(item, Block):
                    self._n -= len(item)
                    self._cond.notify_all()
            if item is self._DONE:
                return
            if isinstance(item, BaseException):
                raise item
            if isinstance(item, _Dropped):
                yield from self._placeholders(item)
            else:
                yield item

    def _placeholders(self, d: _Dropped):
        rate = float(self._source.sample_rate_hz)
        msg = (f"{d.n} samples ({d.blocks} blocks) from t={d.t0_s:.6f} s dropped: processing fell more than "
               f"{self.max_samples} samples ({self.max_samples / rate:g} s) behind the device"
               + (f"; {d.events_left_out} more events of these blocks only counted" if d.events_left_out else ""))
        events = (Event(d.t0_s, "dropped", msg), *d.events)
        for i in range(0, d.n, PLACEHOLDER_BLOCK):
            m = min(PLACEHOLDER_BLOCK, d.n - i)
            nan = np.full(m, np.nan)
            shape = (m, len(self._axes)) if self._axes else m
            yield Block(d.t0_s + np.arange(i, i + m) / rate, np.full(shape, np.nan), np.zeros(shape, bool),
                        {k: nan for k in self._aux_names}, events if i == 0 else (), self._axes)

    def backlog(self, timeout_s: float = 10.0) -> list[Block]:
        """After ``source.close()``: the blocks not yet taken, in order, up to the source's
        end (at most ``timeout_s`` s of waiting for it; a reader held back by a full queue
        is released and stops); an error after the stop is dropped."""
        out: list[Block] = []
        deadline = time.monotonic() + timeout_s
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        while time.monotonic() < deadline:
            with self._cond:
                if not self._items:
                    if not self._thread.is_alive():
                        break
                    self._cond.wait(0.05)
                    continue
                item = self._items.popleft()
            if item is self._DONE:
                break
            if isinstance(item, _Dropped):
                out += self._placeholders(item)
            elif isinstance(item, Block) and (len(item) or item.events):
                out.append(item)
        return out
