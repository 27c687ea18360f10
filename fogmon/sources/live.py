"""What a live source (serial port, CAN bus) shares: a reader thread that drains the
device continuously and reopens it with exponential backoff when it disappears, and a
consumer that turns what was read into Blocks on the sample grid.

The reader thread hands the raw input to the taps (the archive) at once, so a slow
consumer neither overflows the device's small kernel buffer nor delays the archive. It
queues ``("frames", Frames)``, ``("break", samples lost estimate)`` and
``("event", kind, message)`` items; ``blocks()`` turns them into a block every
``block_s`` s while data flows and at least every ``idle_s`` s (possibly empty, carrying
events) while it does not."""
from __future__ import annotations

import queue
import threading
import time
from typing import Iterator

from fogmon.block import Block, Event
from fogmon.errors import FogmonError
from fogmon.sources.frames import Frames
from fogmon.sources.grid import ErrorEvents, GridAssembler


class LiveSource:
    """Base class. Subclasses set ``name``, ``rate_hz``, ``aux_names``, ``grid``, the
    exception types meaning "device lost" (``device_errors``), ``decoder_counters`` (the
    decoder's counters dict, for CRC/bad-input events) and implement ``_open()``,
    ``_read(handle) -> list of queue items`` (calling the taps), ``_close(handle)`` and
    ``_what()`` (the device, for messages and errors)."""

    device_errors: tuple[type[BaseException], ...] = (OSError,)

    def __init__(self, grid: GridAssembler, block_s: float = 0.1, idle_s: float = 0.5,
                 backoff_s: tuple[float, float] = (0.05, 2.0), clock=time.monotonic) -> None:
        self.grid = grid
        self.block_s, self.idle_s, self.backoff_s = block_s, idle_s, backoff_s
        self._clock = clock
        self._taps: list = []
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._own = {"disconnects": 0, "reconnects": 0}

    def add_tap(self, tap) -> None:
        """Register a tap (the archive) for the raw input (adding one twice is a no-op)."""
        if tap not in self._taps:
            self._taps.append(tap)

    # -- subclass hooks ----------------------------------------------------------------
    def _open(self):
        raise NotImplementedError

    def _read(self, handle) -> list:
        raise NotImplementedError

    def _close(self, handle) -> None:
        raise NotImplementedError

    def _what(self) -> str:
        raise NotImplementedError

    def _reconnected(self) -> None:
        """Called in the reader thread after a successful reopen."""

    # -- reader thread ---------------------------------------------------------------
    def _read_loop(self, handle) -> None:
        q, clock = self._q, self._clock
        backoff, down_since = self.backoff_s[0], 0.0
        try:
            while not self._stop.is_set():
                if handle is None:
                    try:
                        handle = self._open()
                    except self.device_errors:
                        self._stop.wait(backoff)
                        backoff = min(2 * backoff, self.backoff_s[1])
                        continue
                    self._own["reconnects"] += 1
                    q.put(("event", "reconnect", f"{self._what()} back after {clock() - down_since:.2f} s"))
                    backoff = self.backoff_s[0]
                    self._reconnected()
                try:
                    items = self._read(handle)
                except self.device_errors as e:
                    self._own["disconnects"] += 1
                    down_since = clock()
                    why = str(e).splitlines()[0] if str(e) else type(e).__name__
                    q.put(("event", "disconnect", f"{self._what()} lost ({why}); retrying"))
                    self._close(handle)
                    handle = None
                    self._stop.wait(backoff)
                    continue
                for it in items:
                    q.put(it)
        finally:
            if handle is not None:
                self._close(handle)
            q.put(("end",))

    # -- consumer --------------------------------------------------------------------
    def blocks(self) -> Iterator[Block]:
        try:
            handle = self._open()
        except self.device_errors as e:
            why = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise FogmonError(f"{self._what()}: cannot open: {why}") from None
        errors = ErrorEvents(self.decoder_counters)      # before the reader starts counting
        self._thread = threading.Thread(target=self._read_loop, args=(handle,), name="fogmon-reader", daemon=True)
        self._thread.start()
        pending: list[Frames] = []
        out: list[Block] = []
        events: list[Event] = []
        last_yield = self._clock()
        ended = False

        def flush():
            nonlocal pending, events
            events += errors.poll(self.grid.t_next_s)
            if pending or events:
                out.append(self.grid.push(Frames.concat(pending, self.aux_names), events))
                pending, events = [], []

        try:
            while not ended:
                timeout = last_yield + self.block_s - self._clock()
                try:
                    item = self._q.get(timeout=timeout) if timeout > 0 else self._q.get_nowait()
                except queue.Empty:
                    item = None
                if item is not None:
                    if item[0] == "frames":
                        pending.append(item[1])
                    elif item[0] == "break":
                        flush()
                        self.grid.mark_break(item[1])
                    elif item[0] == "event":
                        events.append(Event(self.grid.t_next_s, item[1], item[2]))
                    else:
                        ended = True
                    if not ended and self._clock() - last_yield < self.block_s:
                        continue
                now = self._clock()
                if pending or events or ended or now - last_yield >= self.idle_s:
                    flush()
                    if not out:
                        out.append(self.grid.push(Frames.empty(self.aux_names)))
                    while out:
                        yield out.pop(0)
                    last_yield = now
        finally:
            self.close()

    def close(self) -> None:
        """Stop and release the device (thread-safe); ``blocks()`` then ends."""
        self._stop.set()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=2.0)
