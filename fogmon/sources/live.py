"""What a live source (serial port, CAN bus) shares: a reader thread that drains the device
continuously and reopens it with exponential backoff when it disappears, and a consumer
that turns what was read into Blocks on the sample grid.

The reader thread does nothing but read, so the device's small kernel buffer never
overflows while the rest of fogmon is busy; it queues what it read in stream order:
``("data", bytes, t_read_s, drained)`` (a byte stream, decoded by the consumer through
the subclass's ``_consume``; ``drained``: a read at ``t_read_s`` found nothing more
waiting), ``("frames", Frames)`` and ``("break", samples lost estimate)`` (sources that
decode in the reader thread), ``("event", kind, message, counter)`` and ``("reopened",
t_down_s)``. The consumer (``blocks()``) decodes, counts, places on the grid and yields
a block every ``block_s`` s while data flows and at least every ``idle_s`` s (possibly
empty, carrying events) while it does not. Counters and error events are updated by the
consumer only, together with the blocks it yields, so they agree with each other and
with the samples delivered; ``limit(n)`` makes ``blocks()`` end exactly at grid sample
``n`` (a run's ``duration_s``), with nothing after it decoded, counted or handed to the taps."""
from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import replace

from fogmon.block import Block, Event
from fogmon.errors import FogmonError
from fogmon.sources.base import RawTap
from fogmon.sources.frames import Frames
from fogmon.sources.grid import ErrorEvents, GridAssembler


class LiveSource:
    """Base class. Subclasses set ``name``, ``sample_rate_hz``, ``aux_names``, ``grid``, the
    exception types meaning "device lost" (``device_errors``), ``decoder_counters`` (the
    decoder's counters dict, for CRC/bad-input events) and implement ``_open()``,
    ``_read(handle) -> list of queue items``, ``_close(handle)``, ``_what()`` (the
    device, for messages and errors) and, for ``("data", ...)`` items, ``_consume``."""

    device_errors: tuple[type[BaseException], ...] = (OSError,)
    #: a live device has no length and is read as its data arrives (fogmon.sources.base.Source)
    n_samples: int | None = None
    live = True
    name: str
    sample_rate_hz: float
    aux_names: tuple[str, ...]

    @property
    def decoder_counters(self) -> dict[str, int]:
        """The decoder's counters (CRC errors, bad frames, ...), for error events."""
        raise NotImplementedError

    def __init__(self, grid: GridAssembler, block_s: float = 0.1, idle_s: float = 0.5,
                 backoff_s: tuple[float, float] = (0.05, 2.0), clock=time.monotonic) -> None:
        self.grid = grid
        self.block_s, self.idle_s, self.backoff_s = block_s, idle_s, backoff_s
        self._clock = clock
        self._taps: list[RawTap] = []
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._own = {"disconnects": 0, "reconnects": 0}
        self.opened_s: float | None = None   # time.monotonic() when the device was first opened
        self._limit: int | None = None

    @property
    def axes(self) -> tuple[str, ...]:
        """The axes of the blocks (() for a one-axis stream)."""
        return self.grid.axes

    @property
    def pending(self) -> int:
        """Bytes of a partial frame the decoder holds (none for frame-based input)."""
        return 0

    def add_tap(self, tap: RawTap) -> None:
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
        """Called in the consumer when the reopened device's input begins."""

    def limit(self, n_samples: int | None) -> None:
        """End ``blocks()`` after grid sample ``n_samples`` (None: no limit); set before
        ``blocks()`` starts."""
        self._limit = n_samples

    def _room(self) -> int | None:
        """Samples the grid may still take before the limit (None: no limit)."""
        return None if self._limit is None else self._limit - self.grid.next_index

    def _consume(self, item) -> tuple[Block | None, bool]:
        """Decode one queued item of a subclass's own kind (``("data", ...)``) into a
        block within ``_room()``; returns (block or None, limit reached)."""
        raise NotImplementedError

    # -- reader thread ---------------------------------------------------------------
    def _read_loop(self, handle) -> None:
        q, clock = self._q, self._clock
        backoff, down_since = self.backoff_s[0], clock()
        try:
            while not self._stop.is_set():
                if handle is None:
                    try:
                        handle = self._open()
                    except self.device_errors:
                        self._stop.wait(backoff)
                        backoff = min(2 * backoff, self.backoff_s[1])
                        continue
                    q.put(("reopened", down_since))
                    backoff = self.backoff_s[0]
                try:
                    items = self._read(handle)
                except self.device_errors as e:
                    down_since = clock()
                    why = str(e).splitlines()[0] if str(e) else type(e).__name__
                    q.put(("event", "disconnect", f"{self._what()} lost ({why}); retrying", "disconnects"))
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
        errors = self._start()
        parts: list[Block] = []
        events: list[Event] = []
        last_yield = self._clock()
        ended = False
        try:
            while not ended:
                # wait for input until the next yield is due: block_s after the last one when
                # something is held, idle_s when nothing is (a silent device wakes this loop
                # twice a second, not continuously)
                due = last_yield + (self.block_s if parts or events else self.idle_s)
                timeout = due - self._clock()
                try:
                    item = self._q.get(timeout=timeout) if timeout > 0 else self._q.get_nowait()
                except queue.Empty:
                    item = None
                if item is not None:
                    try:
                        ended = self._handle(item, parts, events)
                    except FogmonError:            # (what came before it is delivered first)
                        yield self._take(parts, events, errors)
                        raise
                    if not ended and self._clock() - last_yield < self.block_s:
                        continue
                now = self._clock()
                if parts or events or ended or now - last_yield >= self.idle_s:
                    b = self._take(parts, events, errors)
                    if len(b) or b.events or not ended:
                        yield b
                    last_yield = now
        finally:
            self.close()

    def _start(self) -> ErrorEvents:
        """Open the device (a one-line FogmonError if it cannot be) and start the reader
        thread; the decoder's error events from now on."""
        try:
            handle = self._open()
        except self.device_errors as e:
            why = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise FogmonError(f"{self._what()}: cannot open: {why}") from None
        self.opened_s = time.monotonic()
        errors = ErrorEvents(self.decoder_counters)
        self._thread = threading.Thread(target=self._read_loop, args=(handle,), name="fogmon-reader", daemon=True)
        self._thread.start()
        return errors

    def _handle(self, item: tuple, parts: list[Block], events: list[Event]) -> bool:
        """One item of the reader thread's queue: blocks to ``parts``, events to
        ``events``; True when the stream ended (device end or the ``limit``)."""
        kind = item[0]
        if kind == "end":
            return True
        if kind == "event":
            self._own[item[3]] += 1
            events.append(Event(self.grid.t_next_s, item[1], item[2]))
        elif kind == "reopened":
            self._own["reconnects"] += 1
            events.append(Event(self.grid.t_next_s, "reconnect",
                                f"{self._what()} back after {self._clock() - item[1]:.2f} s"))
            self._reconnected()
        elif kind == "break":
            try:
                self.grid.mark_break(item[1])
            except FogmonError as e:
                raise FogmonError(f"{self._what()}: {e}; the run ends here: start a new one") from None
        else:
            b, full = self._place(item[1]) if kind == "frames" else self._consume(item)
            if b is not None and len(b):
                parts.append(b)
            if full:
                self._stop.set()
                return True
        return False

    def _take(self, parts: list[Block], events: list[Event], errors: ErrorEvents) -> Block:
        """Everything consumed since the last block, as one block with its events (the
        lists are emptied)."""
        tail = self.grid.push(Frames.empty(self.aux_names, self.grid.axes), events + errors.poll(self.grid.t_next_s))
        b = Block.concat([*parts, tail]) if parts else tail
        parts.clear()
        events.clear()
        return b

    def _place(self, frames: Frames) -> tuple[Block, bool]:
        """Frames decoded by the reader thread onto the grid, cut at the limit."""
        b = self.grid.push(frames)
        room = self._room()
        if room is None or room > 0:
            return b, room == 0
        keep = len(b) + room
        self.grid.next_index += room
        cut = b.slice(0, keep)
        return replace(cut, events=tuple(e for e in b.events if keep and e.t_s <= b.t_s[keep - 1])), True

    def close(self) -> None:
        """Stop and release the device (thread-safe); ``blocks()`` then ends."""
        self._stop.set()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=2.0)
