"""Line framing for ASCII protocols: split a byte stream into lines with a bounded
buffer. A line longer than ``max_line`` bytes is garbage: it is dropped (its bytes
counted as skipped) up to the next newline."""
from __future__ import annotations


class LineFramer:
    """``feed(bytes) -> list[bytes]`` complete lines, newline included. Holds at
    most ``max_line`` bytes between calls; ``dropped_bytes`` counts bytes discarded as
    over-long lines (newline included)."""

    def __init__(self, max_line: int = 256) -> None:
        self.max_line = max_line
        self._buf = bytearray()
        self._discarding = False
        self.dropped_bytes = 0
        self.dropped_lines = 0

    @property
    def pending(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytes]:
        buf = self._buf
        buf += data
        lines = []
        start = 0
        while True:
            nl = buf.find(b"\n", start)
            if nl < 0:
                break
            if self._discarding:
                self.dropped_bytes += nl + 1 - start
                self._discarding = False
            elif nl - start > self.max_line:
                self.dropped_bytes += nl + 1 - start
                self.dropped_lines += 1
            else:
                lines.append(bytes(buf[start:nl + 1]))
            start = nl + 1
        del buf[:start]
        if len(buf) > self.max_line:
            if not self._discarding:
                self.dropped_lines += 1
            self.dropped_bytes += len(buf)
            buf.clear()
            self._discarding = True
        return lines
