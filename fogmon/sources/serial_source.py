"""A gyro on a serial port (pyserial): bytes -> codec -> sample grid -> Blocks.

If the port disappears (USB unplugged, adapter reset) it is reopened with backoff (see
fogmon.sources.live); the samples lost meanwhile become invalid placeholders, their
count from the clock (elapsed time x rate minus the frames that did arrive), made exact
by the sequence counter. A silent stretch on an open port (longer than half a counter
wrap, or 0.5 s without a counter) is treated the same way.
"""
from __future__ import annotations

import time

import serial

from fogmon.sources.grid import GridAssembler
from fogmon.sources.live import LiveSource

READ_TIMEOUT_S = 0.05
STALL_S = 0.5


class SerialSource(LiveSource):
    """Live serial gyro. ``port`` is a device path or pyserial URL, ``codec`` one of the
    decoders of fogmon.sources.codecs; ``opener`` (tests, custom transports) returns an
    open pyserial port instead of opening ``port``. Taps get ``raw(bytes)`` for every
    byte received and ``outage(elapsed_s, missing_est)`` for every outage, in stream
    order, from the reader thread. Counters: the codec's (frames_ok, crc_errors,
    bytes_skipped, ...), the grid's (seq_gaps, samples_missing, invalid_samples),
    ``disconnects``, ``reconnects``."""

    device_errors = (serial.SerialException, OSError, ValueError)

    def __init__(self, port: str, baud: int, codec, block_s: float = 0.1, idle_s: float = 0.5,
                 backoff_s: tuple[float, float] = (0.05, 2.0), opener=None, clock=time.monotonic) -> None:
        super().__init__(GridAssembler(codec.rate_hz, codec.seq_modulus, codec.aux_names),
                         block_s, idle_s, backoff_s, clock)
        self.port, self.baud, self.codec = port, int(baud), codec
        self.rate_hz = codec.rate_hz
        self.aux_names = codec.aux_names
        self.name = f"{codec.describe()} on {port}"
        self._opener = opener or (lambda: serial.serial_for_url(port, baudrate=self.baud, timeout=READ_TIMEOUT_S))
        M = codec.seq_modulus
        self._stall_s = min(STALL_S, 0.5 * M / self.rate_hz) if M else STALL_S
        self._last_data: float | None = None
        self._need_break = False

    @property
    def decoder_counters(self) -> dict[str, int]:
        return self.codec.counters

    @property
    def counters(self) -> dict[str, int]:
        return {**self.codec.counters, **self.grid.counters, **self._own}

    def capture_spec(self) -> dict:
        """What the archive needs to write a replayable raw capture."""
        return {"kind": "serial", **self.codec.options(), "port": self.port, "baud": self.baud}

    def _what(self) -> str:
        return f"--serial {self.port}"

    def _open(self):
        return self._opener()

    def _close(self, ser) -> None:
        try:
            ser.close()
        except (serial.SerialException, OSError):
            pass

    def _reconnected(self) -> None:
        self._need_break = True

    def _read(self, ser) -> list:
        data = ser.read(max(1, min(ser.in_waiting, 1 << 16)))
        if not data:
            return []
        now = self._clock()
        frames = self.codec.feed(data)
        items = []
        last = self._last_data
        if last is not None and (self._need_break or now - last > self._stall_s):
            est = (now - last) * self.rate_hz - len(frames)
            items.append(("break", est))
            for tap in self._taps:
                tap.outage(now - last, est)
        self._need_break = False
        for tap in self._taps:
            tap.raw(data)
        if len(frames):
            items.append(("frames", frames))
        self._last_data = now
        return items
