"""Stop signals: Ctrl-C (SIGINT), SIGTERM (``kill``, systemd, docker stop) and SIGHUP (the
terminal closed) all stop a command the same way, as a ``KeyboardInterrupt`` that the
pipeline turns into a clean close (archive flushed, .rrd completed, summary printed).

Only the first stop signal interrupts. Code that must not be torn in the middle (the
pipeline handing one block to every sink) runs ``with shielded():`` - a signal arriving
there interrupts at the end of the block - and once the outputs are being completed
(``closing()``) signals are only noted: a second Ctrl-C cannot cut the .rrd or the
archive short.
Handlers run in the main thread only (Python's rule); other threads are never
interrupted. The CLI installs the handlers (``installed()``); a program that imports
fogmon keeps its own signal handling.
"""
from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator
from typing import Any

#: The signals that stop a command, and how the summary names them.
STOP_SIGNALS: dict[int, str] = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM", signal.SIGHUP: "SIGHUP"}

_state: dict[str, Any] = {"received": None, "shield": 0, "pending": False, "closing": False}


def _handler(signum: int, frame) -> None:
    s = _state
    if s["received"] is not None:
        print(f"fogmon: {STOP_SIGNALS[signum]}: already stopping, completing the outputs", file=sys.stderr)
        return
    s["received"] = signum
    if s["closing"]:
        return
    if s["shield"]:
        s["pending"] = True
        return
    raise KeyboardInterrupt


@contextlib.contextmanager
def installed() -> Iterator[None]:
    """Stop signals handled as described above while the block runs (the CLI's command);
    the previous handlers are restored afterwards. Outside the main thread (where Python
    cannot install handlers) nothing changes."""
    _state.update(received=None, shield=0, pending=False, closing=False)
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, _handler) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h)


@contextlib.contextmanager
def shielded() -> Iterator[None]:
    """A stop signal that arrives while the block runs (in the main thread) interrupts
    at its end instead of in its middle."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _state["shield"] += 1
    try:
        yield
    finally:
        _state["shield"] -= 1
    if not _state["shield"] and _state["pending"] and not _state["closing"]:
        _state["pending"] = False
        raise KeyboardInterrupt


def closing() -> None:
    """From now on stop signals are noted, not raised: the outputs are being completed
    (the pipeline calls this when its run ends, however it ends)."""
    _state["closing"] = True
    _state["pending"] = False


def stop_requested() -> bool:
    """True once a stop signal arrived (for code that waits while ``closing``, such as a
    server that keeps serving after a replay)."""
    return _state["received"] is not None


def stop_name() -> str:
    """How the summary names what stopped the run: 'Ctrl-C' unless SIGTERM or SIGHUP did."""
    return STOP_SIGNALS.get(_state["received"], "Ctrl-C")


def interrupted_exit_code() -> int:
    """128 + the stop signal's number, the shell's convention: 130 after Ctrl-C, 143 after
    SIGTERM, 129 after SIGHUP."""
    return 128 + int(_state["received"] or signal.SIGINT)
