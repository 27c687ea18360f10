"""A gyro on a serial port (pyserial): bytes -> codec -> sample grid -> Blocks.

If the port disappears (USB unplugged, adapter reset) the source keeps retrying with
exponential backoff and carries on when it comes back; the outage is reported as
``disconnect``/``reconnect`` events and the samples lost meanwhile become invalid
placeholders (their count from the clock, made exact by the sequence counter). A silent
stretch on an open port (longer than half a counter wrap, or 0.5 s without a counter) is
treated the same way. Taps (the archive) see every byte received and every outage.
"""
from __future__ import annotations

import threading
import time
from typing import Iterator

import serial

from fogmon.block import Block, Event
from fogmon.errors import FogmonError
from fogmon.sources.frames import Frames
from fogmon.sources.grid import GridAssembler

READ_TIMEOUT_S = 0.05
STALL_S = 0.5


class SerialSource:
    """Live serial gyro. ``port`` is a device path or pyserial URL, ``codec`` one of the
    decoders of fogmon.sources.codecs. Blocks come every ``block_s`` s while data flows,
    and as empty blocks carrying events (or every ``idle_s`` s) while it does not.
    Counters: the codec's (frames_ok, crc_errors, bytes_skipped, ...), the grid's
    (seq_gaps, samples_missing, invalid_samples), ``disconnects`` and ``reconnects``."""

    def __init__(self, port: str, baud: int, codec, block_s: float = 0.1, idle_s: float = 0.5,
                 backoff_s: tuple[float, float] = (0.05, 2.0), clock=time.monotonic) -> None:
        self.port, self.baud, self.codec = port, int(baud), codec
        self.rate_hz = codec.rate_hz
        self.aux_names = codec.aux_names
        self.grid = GridAssembler(self.rate_hz, codec.seq_modulus, codec.aux_names)
        self.name = f"{codec.describe()} on {port}"
        self.block_s, self.idle_s, self.backoff_s = block_s, idle_s, backoff_s
        self._clock = clock
        self._taps: list = []
        self._ser = None
        self._reader: int | None = None   # thread iterating blocks()
        self._stop = threading.Event()
        self._own = {"disconnects": 0, "reconnects": 0}
        M = codec.seq_modulus
        self._stall_s = min(STALL_S, 0.5 * M / self.rate_hz) if M else STALL_S

    @property
    def counters(self) -> dict[str, int]:
        return {**self.codec.counters, **self.grid.counters, **self._own}

    def capture_spec(self) -> dict:
        """What the archive needs to write a replayable raw capture."""
        return {"kind": "serial", **self.codec.options(), "port": self.port, "baud": self.baud}

    def add_tap(self, tap) -> None:
        """``tap.raw(bytes)`` gets every byte received, ``tap.outage(elapsed_s,
        missing_est)`` every outage, in stream order (adding a tap twice is a no-op)."""
        if tap not in self._taps:
            self._taps.append(tap)

    def _open(self):
        return serial.serial_for_url(self.port, baudrate=self.baud, timeout=READ_TIMEOUT_S)

    def blocks(self) -> Iterator[Block]:
        try:
            self._ser = self._open()
        except (serial.SerialException, OSError, ValueError) as e:
            raise FogmonError(f"--serial {self.port}: cannot open: {e}") from None
        self._reader = threading.get_ident()
        try:
            yield from self._run()
        finally:
            self._close_port()
            self._reader = None

    def _run(self) -> Iterator[Block]:
        clock = self._clock
        pending: list[Frames] = []
        ready: list[Block] = []
        events: list[Event] = []
        last_yield = clock()
        last_data = None          # clock time of the last bytes received
        down_since = None
        backoff = self.backoff_s[0]
        next_try = 0.0
        need_break = False

        def flush_pending():
            nonlocal pending, events
            if pending or events:
                ready.append(self.grid.push(Frames.concat(pending, self.aux_names), events))
                pending, events = [], []

        while not self._stop.is_set():
            now = clock()
            if self._ser is None:
                if now >= next_try:
                    try:
                        self._ser = self._open()
                    except (serial.SerialException, OSError, ValueError):
                        next_try = now + backoff
                        backoff = min(2 * backoff, self.backoff_s[1])
                    else:
                        self._own["reconnects"] += 1
                        events.append(Event(self.grid.t_next_s, "reconnect",
                                            f"{self.port} back after {now - down_since:.2f} s"))
                        backoff, need_break = self.backoff_s[0], True
                else:
                    self._stop.wait(min(0.02, next_try - now))
            else:
                try:
                    waiting = self._ser.in_waiting
                    data = self._ser.read(max(1, min(waiting, 1 << 16)))
                except (serial.SerialException, OSError) as e:
                    self._own["disconnects"] += 1
                    down_since = clock()
                    events.append(Event(self.grid.t_next_s, "disconnect",
                                        f"{self.port} lost ({str(e).splitlines()[0] if str(e) else type(e).__name__}); "
                                        f"retrying"))
                    flush_pending()
                    self._close_port()
                    next_try = down_since + backoff
                    continue
                if data:
                    now = clock()
                    frames = self.codec.feed(data)
                    if last_data is not None and (need_break or now - last_data > self._stall_s):
                        flush_pending()
                        elapsed = now - last_data
                        est = elapsed * self.rate_hz - len(frames)
                        self.grid.mark_break(est)
                        for tap in self._taps:
                            tap.outage(elapsed, est)
                    need_break = False
                    for tap in self._taps:
                        tap.raw(data)
                    if len(frames):
                        pending.append(frames)
                    last_data = now
            now = clock()
            if now - last_yield >= self.block_s and (pending or events or ready) or now - last_yield >= self.idle_s:
                flush_pending()
                yield from self._drain(ready)
                last_yield = now
        flush_pending()
        yield from self._drain(ready)

    def _drain(self, ready: list[Block]) -> Iterator[Block]:
        if not ready:
            ready.append(self.grid.push(Frames.empty(self.aux_names)))
        while ready:
            yield ready.pop(0)

    def _close_port(self) -> None:
        if self._ser is not None:
            try:
                self._ser.close()
            except (serial.SerialException, OSError):
                pass
            self._ser = None

    def close(self) -> None:
        """Stop and release the port. Thread-safe: from another thread ``blocks()``
        ends within one read timeout and releases the port itself."""
        self._stop.set()
        if self._reader in (None, threading.get_ident()):
            self._close_port()
