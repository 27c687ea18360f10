"""A gyro on a serial port (pyserial): bytes -> codec -> sample grid -> Blocks.

The reader thread only reads (fogmon.sources.live): every READ_PAUSE_S it takes every
byte waiting, read after read until nothing more is (the kernel hands a tty's input
over in pieces of about 4 KiB), so it keeps up with any device the decoder keeps up
with. The consumer decodes, so the time base comes from the byte stream
(fogmon.sources.grid): a host stall delays bytes but never turns into lost samples. Only
when the port disappears (USB unplugged, adapter reset) and is reopened are the bytes of
the outage gone; the samples lost meanwhile become invalid placeholders, their count
from the clock (elapsed time x rate minus the frames that did arrive), made exact by the
sequence counter. The host clock also watches the counter (grid rule 3: whole wraps
lost without a byte gap) and bounds every gap (``gap_limit`` of the time since the
previous frames could have been sent).
"""
from __future__ import annotations

import contextlib
import copy
import time

import serial

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.sources.base import Codec
from fogmon.sources.grid import GridAssembler, Placed, gap_limit
from fogmon.sources.live import LiveSource

#: the reader sleeps this long (s, a live block's length) between wakes and then takes
#: every byte waiting: 10 wake-ups per second however the device or its USB adapter
#: delivers (a blocking read wakes for every chunk, up to a thousand a second), so the
#: cost per wake (decode, grid, queue) does not grow with the byte rate. The OS buffers
#: the bytes meanwhile; the samples' times come from the byte stream, not from the reads.
READ_PAUSE_S = 0.1
#: with nothing waiting, a read waits at most this long (s) for a first byte
READ_TIMEOUT_S = 0.05
#: bytes one wake takes at most; a longer backlog (after a long host stall) is taken by
#: the next wakes, without a pause
READ_MAX_BYTES = 1 << 20
#: what Linux hands one read of a tty at most (its line discipline's buffer, 4 KiB less
#: one byte: ``in_waiting`` shows no more): after a read that took this much, more may be
#: on its way from the driver, so the reader waits for it (up to READ_TIMEOUT_S) before it
#: counts the port drained, and the next wake comes after READ_PAUSE_S / 10
READ_BURST_BYTES = 4095
#: how late (s) the bytes of a device may reach a read that found nothing more waiting
#: (USB latency, the kernel handing input over, a busy host), when the clock bounds a gap
CLOCK_SLACK_S = 1.0


class SerialSource(LiveSource):
    """Live serial gyro. ``port`` is a device path or pyserial URL, ``codec`` one of the
    decoders of fogmon.sources.codecs (``protocols.make_codec``); ``opener`` (tests, custom transports) returns an
    open pyserial port (``read``, ``in_waiting``, ``close``; a read timeout keeps a silent
    port from blocking the reader) instead of opening ``port``; ``read_pause_s`` is the
    sleep between wakes (READ_PAUSE_S; 0 for a port that paces itself). Taps get
    ``raw(bytes)`` for every byte decoded,
    ``outage(elapsed_s, missing_est)`` for every reopen of the port and ``placed(...)``
    for every gap the host clock decided (grid.Placed), in stream order.
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
        self._drained = True                  # (reader) the last wake took everything waiting
        self._burst = False                   # (reader) ... and at least READ_BURST_BYTES
        self._ref_t: float | None = None      # (consumer) when a read last found nothing more waiting (s)
        self._frames_after: float | None = None  # the last frames pushed were sent after this (s)

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
        """One wake: every byte waiting, as one ``("data", bytes, t_s, drained)`` item;
        ``drained``: a read at clock time ``t_s`` found nothing more waiting (so every byte
        sent before then, less the delivery latency, is in the item or before it)."""
        pause = self.read_pause_s / (10 if self._burst else 1)
        if pause and self._drained and self._stop.wait(pause):
            return []
        chunks: list[bytes] = []
        total = waiting = last = 0
        t = self._clock()
        while total < READ_MAX_BYTES:
            t = self._clock()
            waiting = ser.in_waiting
            if waiting:
                data = ser.read(min(waiting, READ_MAX_BYTES - total))
            elif last >= READ_BURST_BYTES:       # the kernel may not have handed the rest over yet
                data = ser.read(1)
            else:
                break
            if not data:
                break
            chunks.append(data)
            total += len(data)
            last = len(data)
        self._drained, self._burst = not waiting, total >= READ_BURST_BYTES
        if chunks:
            return [("data", b"".join(chunks), t if self._drained else self._clock(), self._drained)]
        data = ser.read(1)    # nothing waiting: wait up to the port's timeout (a vanished device raises here)
        self._drained = not data
        return [("data", data, self._clock(), False)] if data else []

    # -- consumer ------------------------------------------------------------------------
    def _consume(self, item) -> tuple[Block | None, bool]:
        _, data, t, drained = item
        if self._limit is None:
            return self._apply(data, t, drained), False
        saved = self._save()
        b = self._decode(data, t, drained)
        if self.grid.next_index < self._limit:
            self._tap(data, b)
            return b[0], False
        # the run ends in this chunk: at the end of the last frame that fits, so that nothing
        # after it (garbage, CRC failures, a partial frame) is counted or archived

        def index_after(p: int) -> int:
            self._load(saved)
            self._decode(data[:p], t, False)
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
        return self._apply(data[:lo], t, False) if lo else None, True

    def _apply(self, data: bytes, t: float, drained: bool) -> Block:
        b = self._decode(data, t, drained)
        self._tap(data, b)
        return b[0]

    def _decode(self, data: bytes, t: float, drained: bool) -> tuple[Block, tuple[float, float] | None, list[Placed]]:
        """Feed ``data`` (read at clock time ``t``; ``drained``: nothing more was waiting
        then) to the codec and the grid: (block, the outage (elapsed s, samples lost
        estimate) marked before its first frame, the gaps the clock decided)."""
        frames = self.codec.feed(data)
        outage = None
        if self._need_break and len(frames):
            if self._last_t is not None:    # (nothing came before the outage: no gap to place)
                elapsed = t - self._last_t
                outage = (elapsed, max(0.0, elapsed * self.sample_rate_hz - len(frames)))
                try:
                    self.grid.mark_break(outage[1])
                except FogmonError as e:
                    raise FogmonError(f"{self._what()}: {e}; the run ends here: start a new one") from None
            self._need_break = False
            self._ref_t = self._frames_after = None
        if not self._need_break:
            self._last_t = t
        since = self._frames_after
        self.grid.max_gap = None if since is None else gap_limit(
            self.sample_rate_hz, t - since + CLOCK_SLACK_S, self.grid.seq_modulus)
        b = self.grid.push(frames)
        if len(frames):
            self._frames_after = self._ref_t   # these frames were sent after the previous full read
        if drained:
            self._ref_t = t
            if len(frames):
                self.grid.observe_clock(t)
        return b, outage, self.grid.decisions

    def _tap(self, data: bytes, decoded) -> None:
        _, outage, placed = decoded
        for tap in self._taps:
            if outage is not None:
                tap.outage(*outage)
            for p in placed:
                tap.placed(*p)
            tap.raw(data)

    def _save(self) -> tuple:
        return (_snapshot(self.codec), _snapshot(self.grid), self._need_break, self._last_t, self._ref_t,
                self._frames_after)

    def _load(self, saved: tuple) -> None:
        _restore(self.codec, saved[0])
        _restore(self.grid, saved[1])
        self._need_break, self._last_t, self._ref_t, self._frames_after = saved[2:]


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
