"""Fake serial gyros on a pseudo-terminal for the source tests: a KVH DSP-1760 sending
Format A frames in rate mode (deg/s) where frame k carries the value k on every axis, so
a decoded sample tells which frame it came from (rate_dph / 3600 = k). Faults can be
injected per frame; the device can be unplugged (the pty disappears) and plugged again
under the same path, as a USB adapter does."""
from __future__ import annotations

import os
import threading
import time
import tty

from fogmon.sources.codecs.kvh import encode_frame

#: frame k carries k deg/s, beyond a real DSP-1760's range (+-490 deg/s) once k > 735: decoders of
#: these streams lift the plausibility gate to this (deg/h) so that every frame stays a sample
MAX_RATE_DPH = 1e9


def frame_k(k: int, fmt: str = "a") -> bytes:
    return encode_frame(fmt, k % 128, (k, k, k), temp_c=20 + k % 7, timestamp_us=k * 1000)


def stream(n: int, faults: dict[int, str] | None = None, start: int = 0, fmt: str = "a") -> tuple[bytes, list[int]]:
    """Bytes of frames start..start+n-1 with ``faults`` {k: 'drop'|'corrupt'|'truncate'|
    'garbage'} applied, and the list of k whose frames went out intact."""
    out, intact = [], []
    faults = faults or {}
    for k in range(start, start + n):
        f = frame_k(k, fmt)
        kind = faults.get(k)
        if kind == "drop":
            continue
        if kind == "corrupt":
            f = f[:10] + bytes([f[10] ^ 0x5A]) + f[11:]
        elif kind == "truncate":
            f = f[:20]
        elif kind == "garbage":
            out.append(bytes((k * 37 + i) % 200 + 1 for i in range(13)))  # never 0xFE
            intact.append(k)
        else:
            intact.append(k)
        out.append(f)
    return b"".join(out), intact


def write_all(fd: int, data: bytes, timeout_s: float = 2.0) -> None:
    """Write every byte to the non-blocking ``fd`` (a full pty master takes part of a
    write); TimeoutError when nobody has read for ``timeout_s`` (the monitor is gone:
    never block a test forever)."""
    view = memoryview(data)
    deadline = time.monotonic() + timeout_s
    while view:
        try:
            view = view[os.write(fd, view):]
            deadline = time.monotonic() + timeout_s
        except BlockingIOError:
            if time.monotonic() > deadline:
                raise TimeoutError("nobody reads the fake device's pty") from None
            time.sleep(0.001)


def open_pty() -> tuple[int, int, str]:
    """(non-blocking raw master fd, raw slave fd, slave path)."""
    m, s = os.openpty()
    tty.setraw(m)
    tty.setraw(s)
    os.set_blocking(m, False)
    return m, s, os.ttyname(s)


def has_open(pid: int, tty_path: str) -> bool:
    """Whether process ``pid`` holds ``tty_path`` open (Linux /proc)."""
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return False
    for fd in fds:
        try:
            if os.readlink(f"/proc/{pid}/fd/{fd}") == tty_path:
                return True
        except OSError:
            pass
    return False


class FakeKvh:
    """A KVH on a pty reachable as ``self.link`` (a symlink, like /dev/serial/by-id/...).
    ``run_for(seconds)`` in a thread sends frames at ``sample_rate_hz`` paced by the clock
    (k = frames due since start); ``unplug()``/``plug()`` remove and recreate the pty.
    ``sent`` lists every k written while plugged in."""

    def __init__(self, directory: str, sample_rate_hz: float = 200.0) -> None:
        self.link = os.path.join(directory, "ttyFAKEKVH")
        self.sample_rate_hz = sample_rate_hz
        self.sent: list[int] = []
        self.lock = threading.Lock()
        self.master = self.slave = None
        self.plug()

    def plug(self) -> None:
        m, s, self.tty = open_pty()
        os.symlink(self.tty, self.link)
        with self.lock:
            self.master, self.slave = m, s

    def unplug(self) -> None:
        with self.lock:
            os.unlink(self.link)
            os.close(self.master)
            os.close(self.slave)
            self.master = self.slave = None

    def send_due(self, t0: float, k_next: int) -> int:
        """Send every frame due by now (k < (now - t0) * rate); returns the next k.
        TimeoutError (nothing recorded as sent) when the reader is gone."""
        due = int((time.monotonic() - t0) * self.sample_rate_hz)
        with self.lock:
            if self.master is not None and due > k_next:
                write_all(self.master, b"".join(frame_k(k) for k in range(k_next, due)))
                self.sent.extend(range(k_next, due))
        return max(due, k_next)

    def close(self) -> None:
        if self.master is not None:
            self.unplug()
