"""Sockets and polling for tests of servers and subprocesses: a free port, the
addresses listening on a port, waiting for a condition (the deadline only guards
against a hang)."""
from __future__ import annotations

import socket
import time


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening(port):
    """IPv4 addresses with a socket listening on ``port`` (Linux /proc/net/tcp)."""
    out = set()
    with open("/proc/net/tcp") as fh:
        for line in fh.readlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            addr, p = local.split(":")
            if state == "0A" and int(p, 16) == port:          # 0A = LISTEN
                out.add(socket.inet_ntoa(bytes.fromhex(addr)[::-1]))
    return out


def wait_until(cond, what, timeout_s=120.0):
    """Poll ``cond`` (the deadline only guards against a hang; it is not what is tested)."""
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, what
        time.sleep(0.05)
