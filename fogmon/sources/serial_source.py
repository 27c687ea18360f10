"""A gyro on a serial port (pyserial): bytes -> codec -> sample grid -> Blocks.

A reader thread drains the port continuously (so a slow consumer never makes the
kernel's small tty buffer overflow), decodes, and hands the raw bytes to the taps (the
archive) at once. If the port disappears (USB unplugged, adapter reset) it keeps
retrying with exponential backoff and carries on when it comes back; the outage is
reported as ``disconnect``/``reconnect`` events and the samples lost meanwhile become
invalid placeholders (their count from the clock, made exact by the sequence counter).
A silent stretch on an open port (longer than half a counter wrap, or 0.5 s without a
counter) is treated the same way.
"""
from __future__ import annotations

import queue
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
    decoders of fogmon.sources.codecs; ``opener`` (tests, custom transports) returns an
    open pyserial port instead of opening ``port``. Blocks come every ``block_s`` s while
    data flows, and at least every ``idle_s`` s (possibly empty, carrying events) while it
    does not. Counters: the codec's (frames_ok, crc_errors, bytes_skipped, ...), the
    grid's (seq_gaps, samples_missing, invalid_samples), ``disconnects``, ``reconnects``."""

    def __init__(self, port: str, baud: int, codec, block_s: float = 0.1, idle_s: float = 0.5,
                 backoff_s: tuple[float, float] = (0.05, 2.0), opener=None, clock=time.monotonic) -> None:
        self.port, self.baud, self.codec = port, int(baud), codec
        self.rate_hz = codec.rate_hz
        self.aux_names = codec.aux_names
        self.grid = GridAssembler(self.rate_hz, codec.seq_modulus, codec.aux_names)
        self.name = f"{codec.describe()} on {port}"
        self.block_s, self.idle_s, self.backoff_s = block_s, idle_s, backoff_s
        self._opener = opener or (lambda: serial.serial_for_url(port, baudrate=self.baud, timeout=READ_TIMEOUT_S))
        self._clock = clock
        self._taps: list = []
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
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
        missing_est)`` every outage, in stream order, from the reader thread (adding a
        tap twice is a no-op)."""
        if tap not in self._taps:
            self._taps.append(tap)

    # -- reader thread ---------------------------------------------------------------
    def _read_loop(self, ser) -> None:
        clock, q = self._clock, self._q
        last_data = None
        backoff = self.backoff_s[0]
        need_break = False
        down_since = 0.0
        try:
            while not self._stop.is_set():
                if ser is None:
                    try:
                        ser = self._opener()
                    except (serial.SerialException, OSError, ValueError):
                        self._stop.wait(backoff)
                        backoff = min(2 * backoff, self.backoff_s[1])
                        continue
                    self._own["reconnects"] += 1
                    q.put(("event", "reconnect", f"{self.port} back after {clock() - down_since:.2f} s"))
                    backoff, need_break = self.backoff_s[0], True
                try:
                    data = ser.read(max(1, min(ser.in_waiting, 1 << 16)))
                except (serial.SerialException, OSError) as e:
                    self._own["disconnects"] += 1
                    down_since = clock()
                    why = str(e).splitlines()[0] if str(e) else type(e).__name__
                    q.put(("event", "disconnect", f"{self.port} lost ({why}); retrying"))
                    _close(ser)
                    ser = None
                    self._stop.wait(backoff)
                    continue
                if not data:
                    continue
                now = clock()
                frames = self.codec.feed(data)
                if last_data is not None and (need_break or now - last_data > self._stall_s):
                    elapsed = now - last_data
                    est = elapsed * self.rate_hz - len(frames)
                    q.put(("break", est))
                    for tap in self._taps:
                        tap.outage(elapsed, est)
                need_break = False
                for tap in self._taps:
                    tap.raw(data)
                if len(frames):
                    q.put(("frames", frames))
                last_data = now
        finally:
            _close(ser)
            q.put(("end",))

    # -- consumer --------------------------------------------------------------------
    def blocks(self) -> Iterator[Block]:
        try:
            ser = self._opener()
        except (serial.SerialException, OSError, ValueError) as e:
            raise FogmonError(f"--serial {self.port}: cannot open: {e}") from None
        self._thread = threading.Thread(target=self._read_loop, args=(ser,), name="fogmon-serial", daemon=True)
        self._thread.start()
        pending: list[Frames] = []
        out: list[Block] = []
        events: list[Event] = []
        last_yield = self._clock()
        ended = False

        def flush():
            nonlocal pending, events
            if pending or events:
                out.append(self.grid.push(Frames.concat(pending, self.aux_names), events))
                pending, events = [], []

        try:
            while not ended:
                timeout = max(0.0, last_yield + self.block_s - self._clock())
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
        """Stop and release the port (thread-safe); ``blocks()`` then ends."""
        self._stop.set()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=2.0)


def _close(ser) -> None:
    if ser is not None:
        try:
            ser.close()
        except (serial.SerialException, OSError):
            pass
