"""Fixtures shared by the test modules (helpers they import: tests/helpers/)."""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


@pytest.fixture
def fake_kvh():
    # every 500th frame with a bad CRC
    p = subprocess.Popen([sys.executable, str(HERE / "helpers" / "fake_kvh.py"), "30", "500"], stdout=subprocess.PIPE,
                         text=True)
    try:
        yield p.stdout.readline().strip()
    finally:
        p.kill()
        p.wait(timeout=10)


@pytest.fixture
def process_groups():
    """Processes a test starts (in their own session): killed with their group at the end,
    so a failing test leaves no server behind."""
    procs = []
    yield procs
    for p in procs:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGKILL)
        p.wait(timeout=30)
