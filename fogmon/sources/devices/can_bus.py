"""A live CAN gyro on any python-can interface: a reader thread drains the bus and
decodes its frames with the DBC codec (fogmon.sources.codecs.can); the frames go on
the sample grid as fogmon.sources.live describes."""
from __future__ import annotations

import contextlib
from typing import Any

import can

from fogmon.sources.codecs.can import CanDecoder
from fogmon.sources.grid import GridAssembler
from fogmon.sources.live import LiveSource


class CanSource(LiveSource):
    """Live CAN gyro on any python-can interface, read by a reader thread that reopens
    the bus with backoff when it fails (``disconnect``/``reconnect`` events; see
    fogmon.sources.live). Taps (the archive) get every frame received via
    ``tap.frame(msg)``. Counters: the decoder's, the grid's, ``disconnects``,
    ``reconnects``."""

    device_errors = (can.CanError, OSError, ValueError, ImportError)

    def __init__(self, channel: str, interface: str, db, bitrate: int | None = None, dbc_path: str | None = None,
                 block_s: float = 0.1, idle_s: float = 0.5, backoff_s=(0.05, 2.0), **decoder_options) -> None:
        self.decoder = CanDecoder(db, **decoder_options)
        super().__init__(GridAssembler(self.decoder.sample_rate_hz, self.decoder.seq_modulus, self.decoder.aux_names,
                                       axes=self.decoder.axes), block_s, idle_s, backoff_s)
        self.channel, self.interface, self.bitrate, self.dbc_path = channel, interface, bitrate, dbc_path
        self.sample_rate_hz = self.decoder.sample_rate_hz
        self.aux_names = self.decoder.aux_names
        self.name = f"{self.decoder.describe()} on {interface}:{channel}"

    @property
    def decoder_counters(self) -> dict[str, int]:
        return self.decoder.counters

    @property
    def counters(self) -> dict[str, int]:
        return {**self.decoder.counters, **self.grid.counters, **self._own}

    def capture_spec(self) -> dict:
        return {"kind": "can", **self.decoder.options(), "dbc_path": self.dbc_path,
                "channel": self.channel, "interface": self.interface}

    def _what(self) -> str:
        return f"--can {self.channel} --interface {self.interface}"

    def _open(self):
        kw: dict[str, Any] = {"bitrate": self.bitrate} if self.bitrate else {}
        return can.Bus(interface=self.interface, channel=self.channel, **kw)

    def _close(self, bus) -> None:
        with contextlib.suppress(Exception):  # a dead bus may fail to shut down; it is gone either way
            bus.shutdown()

    def _read(self, bus) -> list:
        m = bus.recv(timeout=0.05)
        msgs = []
        while m is not None:
            msgs.append(m)
            for tap in self._taps:
                tap.frame(m)
            if len(msgs) >= 1024:
                break
            try:
                m = bus.recv(timeout=0.0)
            except self.device_errors:   # keep what was read; the next call meets the error again
                break
        items: list[tuple] = []
        for brk, frames in self.decoder.feed(msgs):
            if brk is not None:
                items.append(("break", brk))
            items.append(("frames", frames))
        return items
