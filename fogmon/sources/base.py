"""What every source (serial gyro, CAN gyro, replay, simulator) provides.

The rest of fogmon cannot tell a live gyro from a replay: it iterates ``blocks()``
and reads ``counters``. Sources convert to deg/h and s at this boundary and insert
invalid placeholder samples for anything lost (see fogmon.block)."""
from __future__ import annotations

from typing import Iterator, Protocol

from fogmon.block import Block


class Source(Protocol):
    #: human-readable description, e.g. "KVH DSP-1760 format A on /dev/ttyUSB0, axis z"
    name: str
    #: nominal sample rate in Hz (the uniform grid that Block samples sit on)
    rate_hz: float
    #: running counts: frames_ok, crc_errors, bytes_skipped, seq_gaps, invalid_samples, ...
    counters: dict[str, int]

    def blocks(self) -> Iterator[Block]:
        """Yield blocks until the source ends (end of file, --duration-s, close())."""
        ...

    def close(self) -> None:
        """Stop and release the device/file; ``blocks()`` then ends."""
        ...
