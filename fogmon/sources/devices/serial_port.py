"""A gyro on a serial port (pyserial): bytes -> codec -> sample grid -> Blocks.

The reader thread only reads (fogmon.sources.live); the consumer decodes, so the time
base comes from the byte stream (fogmon.sources.grid): a host stall delays bytes but
never turns into lost samples. Only when the port disappears (USB unplugged, adapter
reset) and is reopened are the bytes of the outage gone; the samples lost meanwhile
become invalid placeholders, their count from the clock (elapsed time x rate minus the
frames that did arrive), made exact by the sequence counter.
"""
from __future__ import annotations

import contextlib
import copy
import time

import serial

from fogmon.block import Block
from fogmon.sources.base import Codec
from fogmon.sources.grid import GridAssembler
from fogmon.sources.live import LiveSource

#: the reader sleeps this long (s, a live block's length) between reads and then takes
#: every byte waiting: 10 wake-ups per second however the device or its USB adapter
#: delivers (a blocking read wakes for every chunk, up to a thousand a second), so the
#: cost per read (decode, grid, queue) does not grow with the byte rate. The OS buffers
#: the bytes meanwhile; the samples' times come from the byte stream, not from the reads.
READ_PAUSE_S = 0.1
#: with nothing waiting, a read waits at most this long (s) for a first byte
READ_TIMEOUT_S = 0.05
#: bytes taken per read at most (a backlog after a host stall is taken in several reads)
READ_MAX_BYTES = 1 << 16


class SerialSource(LiveSource):
    """Live serial gyro. ``port`` is a device path or pyserial URL, ``codec`` one of the
    decoders of fogmon.sources.codecs (``protocols.make_codec``); ``opener`` (tests, custom transports) returns an
    open pyserial port (``read``, ``in_waiting``, ``close``; a read timeout keeps a silent
    port from blocking the reader) instead of opening ``port``; ``read_pause_s`` is the
    sleep between reads (READ_PAUSE_S; 0 for a port that paces itself). Taps get
    ``raw(bytes)`` for every byte decoded and
    ``outage(elapsed_s, missing_est)`` for every reopen of the port, in stream order.
    Counters: the codec's (frames_ok, crc_errors, bytes_skipped, ...), the grid's
    (seq_gaps, samples_missing, invalid_samples), ``disconnects``, ``reconnects``."""

    device_errors = (serial.SerialException, OSError, ValueError)

    def __init__(self, port: str, baud: int, codec: Codec, block_s: float = 0.1, idle_s: float = 0.5,
                 backoff_s: tuple[float, float] = (0.05, 2.0), opener=None, clock=time.monotonic,
                 read_pause_s: float = READ_PAUSE_S) -> None:
        super().__init__(GridAssembler(codec.sample_rate_hz, codec.seq_modulus, codec.aux_names, axes=codec.axes),
                         block_s, idle_s, backoff_s, clock)
        self.port, self.baud, self.codec = port, int(baud), codec
        self.sample_rate_hz = codec.sample_rate_hz
        self.aux_names = codec.aux_names
        self.name = f"{codec.describe()} on {port}"
        self._opener = opener or (lambda: serial.serial_for_url(port, baudrate=self.baud, timeout=READ_TIMEOUT_S))
        self._last_t: float | None = None     # when the last byte before now was read (s, clock)
        self._need_break = False              # the port was reopened: the next frame follows an outage
        self.read_pause_s = read_pause_s

    @property
    def decoder_counters(self) -> dict[str, int]:
        return self.codec.counters

    @property
    def pending(self) -> int:
        return self.codec.pending

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
        with contextlib.suppress(serial.SerialException, OSError):
            ser.close()

    def _reconnected(self) -> None:
        self._need_break = True

    def _read(self, ser) -> list:
        if self.read_pause_s and self._stop.wait(self.read_pause_s):
            return []
        data = ser.read(min(ser.in_waiting, READ_MAX_BYTES) or 1)
        return [("data", data, self._clock())] if data else []

    # -- consumer ------------------------------------------------------------------------
    def _consume(self, item) -> tuple[Block | None, bool]:
        _, data, t = item
        if self._limit is None:
            return self._apply(data, t), False
        saved = self._save()
        b = self._decode(data, t)
        if self.grid.next_index < self._limit:
            self._tap(data, b)
            return b[0], False
        # the run ends in this chunk: at the end of the last frame that fits, so that nothing
        # after it (garbage, CRC failures, a partial frame) is counted or archived

        def index_after(p: int) -> int:
            self._load(saved)
            self._decode(data[:p], t)
            return self.grid.next_index

        lo, hi = 0, len(data)              # the longest prefix that stays within the limit
        while lo < hi:
            mid = (lo + hi + 1) // 2
            lo, hi = (mid, hi) if index_after(mid) <= self._limit else (lo, mid - 1)
        target = index_after(lo)
        lo, hi = 0, lo                     # the shortest prefix that gets there
        while lo < hi:
            mid = (lo + hi) // 2
            lo, hi = (lo, mid) if index_after(mid) >= target else (mid + 1, hi)
        self._load(saved)
        return self._apply(data[:lo], t) if lo else None, True

    def _apply(self, data: bytes, t: float) -> Block:
        b = self._decode(data, t)
        self._tap(data, b)
        return b[0]

    def _decode(self, data: bytes, t: float) -> tuple[Block, tuple[float, float] | None]:
        """Feed ``data`` (read at clock time ``t``) to the codec and the grid: (block,
        the outage (elapsed s, samples lost estimate) marked before its first frame)."""
        frames = self.codec.feed(data)
        outage = None
        if self._need_break and len(frames):
            if self._last_t is not None:    # (nothing came before the outage: no gap to place)
                elapsed = t - self._last_t
                outage = (elapsed, max(0.0, elapsed * self.sample_rate_hz - len(frames)))
                self.grid.mark_break(outage[1])
            self._need_break = False
        if not self._need_break:
            self._last_t = t
        return self.grid.push(frames), outage

    def _tap(self, data: bytes, decoded) -> None:
        outage = decoded[1]
        for tap in self._taps:
            if outage is not None:
                tap.outage(*outage)
            tap.raw(data)

    def _save(self) -> tuple:
        return _snapshot(self.codec), _snapshot(self.grid), self._need_break, self._last_t

    def _load(self, saved: tuple) -> None:
        _restore(self.codec, saved[0])
        _restore(self.grid, saved[1])
        self._need_break, self._last_t = saved[2], saved[3]


def _snapshot(obj) -> dict:
    """The state of a codec or grid: its attributes, mutable ones copied (nested fogmon
    objects such as a line framer by their own snapshot)."""
    out = {}
    for k, v in vars(obj).items():
        if isinstance(v, (dict, list, bytearray, set)):
            v = copy.copy(v)
        elif type(v).__module__.startswith("fogmon.") and hasattr(v, "__dict__"):
            v = (type(v), _snapshot(v))
        out[k] = v
    return out


def _restore(obj, state: dict) -> None:
    """Put ``obj`` back in ``state`` (from ``_snapshot``); dicts are refilled in place, so
    whoever holds them (error events hold the codec's counters) sees the restored values."""
    for k, v in state.items():
        cur = getattr(obj, k, None)
        if isinstance(v, tuple) and len(v) == 2 and isinstance(v[0], type) and isinstance(v[1], dict):
            _restore(cur, v[1])
        elif isinstance(cur, dict) and isinstance(v, dict):
            cur.clear()
            cur.update(v)
        elif isinstance(cur, bytearray):
            cur[:] = v
        else:
            setattr(obj, k, copy.copy(v) if isinstance(v, (dict, list, set, bytearray)) else v)
