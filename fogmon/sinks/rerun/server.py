"""The Rerun gRPC server process of ``--serve`` (the rerun binary in its own process
group, dying with fogmon), the checks that a port is free and that a ``--connect`` URL
has a listener, and stopping a process group.
"""
from __future__ import annotations

import errno
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time

from fogmon.errors import FogmonError

_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def start_grpc_server(bind: str, port: int, timeout_s: float = 10.0) -> tuple[subprocess.Popen, str]:
    """Start a headless Rerun gRPC server (`rerun --serve-grpc`) listening on ``bind:port``;
    returns the process and the URL SDKs and viewers connect to. A port already in use
    is a one-line FogmonError before anything starts. The server is the rerun binary
    itself (not the Python launcher, which would run it as a grandchild), in its own
    process group, and on Linux dies with the thread that started it, even when fogmon
    is killed with SIGKILL (prctl PR_SET_PDEATHSIG): no server is ever left behind."""
    check_port_free(bind, port)
    # a file that lives as long as the server, not a pipe: a long-running server must never block on its log
    log = tempfile.TemporaryFile()  # noqa: SIM115
    proc = subprocess.Popen([_rerun_binary(), "--serve-grpc", "--bind", bind, "--port", str(port)],
                            start_new_session=True, preexec_fn=_die_with_parent(), stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=log)
    host = "127.0.0.1" if bind in ("0.0.0.0", "::", "") else bind
    deadline = time.monotonic() + timeout_s
    try:
        with log:
            while time.monotonic() < deadline:
                if proc.poll() is not None:
                    log.seek(0)
                    lines = _ANSI.sub("", log.read().decode(errors="replace")).strip().splitlines()
                    raise FogmonError(f"`serve`: rerun server on {bind}:{port} exited: "
                                      f"{lines[-1].strip() if lines else proc.returncode}")
                try:
                    with socket.create_connection((host, port), timeout=0.2):
                        if proc.poll() is None:      # our server answered, not one that held the port
                            return proc, f"rerun+http://{host}:{port}/proxy"
                except OSError:
                    time.sleep(0.1)
        raise FogmonError(f"`serve`: rerun server did not start listening on {bind}:{port} within {timeout_s:g} s")
    except BaseException:   # also Ctrl-C while waiting: leave no server behind
        stop_process_group(proc)
        raise


def check_port_free(bind: str, port: int) -> None:
    """A one-line FogmonError unless a server could listen on ``bind:port`` now."""
    try:
        family, kind, proto, _, addr = socket.getaddrinfo(bind or None, port, type=socket.SOCK_STREAM,
                                                          flags=socket.AI_PASSIVE)[0]
    except socket.gaierror as e:
        raise FogmonError(f"`bind` {bind}: not an address to listen on ({e.strerror})") from None
    with socket.socket(family, kind, proto) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)   # as servers do: TIME_WAIT is no conflict
        try:
            s.bind(addr)
        except OSError as e:
            if e.errno == errno.EADDRINUSE:
                raise FogmonError(f"`serve`: port {port} on {bind} is already in use (another fogmon `serve` or "
                                  f"Rerun server/viewer; to send to a running viewer use `connect`); stop it or "
                                  f"give another `port`") from None
            raise FogmonError(f"`serve`: cannot listen on {bind}:{port}: {e.strerror}") from None


def _rerun_binary() -> str:
    """The rerun executable shipped with rerun-sdk (what its `rerun` launcher runs), or
    RERUN_CLI_PATH as the launcher honours it."""
    import rerun_cli

    exe = os.environ.get("RERUN_CLI_PATH") or os.path.join(os.path.dirname(rerun_cli.__file__), "rerun")
    if not os.path.isfile(exe):
        raise FogmonError(f"`serve`: the rerun executable of rerun-sdk is missing ({exe})")
    return exe


def _die_with_parent():
    """A ``preexec_fn`` (Linux; None elsewhere) giving the child SIGKILL when the thread
    that started it ends, which includes fogmon being killed. Everything it calls is
    resolved before the fork."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    prctl = ctypes.CDLL(None, use_errno=True).prctl
    parent = os.getpid()
    pr_set_pdeathsig, sigkill = 1, int(signal.SIGKILL)

    def preexec() -> None:
        prctl(pr_set_pdeathsig, sigkill)
        if os.getppid() != parent:   # fogmon died before the death signal was armed
            os._exit(1)

    return preexec


def _check_listening(url: str, timeout_s: float = 2.0) -> None:
    """A one-line error unless something accepts TCP connections at the URL's host:port
    (a Rerun SDK would otherwise wait, then block at the end, for a viewer that is not there)."""
    from urllib.parse import urlsplit

    try:
        u = urlsplit(url)
        host, port = u.hostname, u.port
    except ValueError:
        host = port = None
    if not host or not port:
        raise FogmonError(f"`connect` {url}: expected a URL like rerun+http://127.0.0.1:9876/proxy")
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError:
        raise FogmonError(f"`connect` {url}: no Rerun viewer listening at {host}:{port} "
                          f"(start one with `rerun`, or use `serve` or `rrd`)") from None


def stop_process_group(proc: subprocess.Popen, timeout_s: float = 5.0) -> None:
    """Terminate a process started with ``start_new_session=True`` and all its children."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=timeout_s)
            return
        except subprocess.TimeoutExpired:
            continue
