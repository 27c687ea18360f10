"""Issue 32.5: one archive, one writer. The archive folder is locked before the "already
holds an archive" check, so a second writer (another process, or another Archive in
this one) gets a one-line error naming the holder; the lock of a writer that died is
free again; a run leaves no lock file behind."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.formats.archive import LOCK
from fogmon.formats.replay_log import read_replay_log
from fogmon.sinks.archive import Archive


class FakeSource:
    name, sample_rate_hz, counters, axes = "fake gyro", 10.0, {}, ()


def _block(k0: int, n: int) -> Block:
    t = (k0 + np.arange(n)) / 10.0
    return Block.make(t, t * 100, None, {"temp_c": np.full(n, 21.5)})


def _holder(folder: Path) -> subprocess.Popen:
    """Another process holding an Archive of ``folder`` open (it says "ready" once it has)."""
    code = ("import sys, time\nfrom fogmon.sinks.archive import Archive\n"
            "class S:\n    name, sample_rate_hz, counters, axes = 'other', 10.0, {}, ()\n"
            f"a = Archive({str(folder)!r}, S())\nprint('ready', flush=True)\nsys.stdin.read()\na.close()\n")
    p = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONPATH": str(REPO)})
    assert p.stdout is not None and p.stdout.readline() == "ready\n"
    return p


def test_a_second_writer_in_this_process_is_refused(tmp_path):
    folder = tmp_path / "a"
    with Archive(str(folder), FakeSource()) as first:
        with pytest.raises(FogmonError, match=rf"^archive {folder}: another fogmon \(pid {os.getpid()} on .+\) "
                                              r"is writing an archive there; give another folder$"):
            Archive(str(folder), FakeSource())
        first.write(_block(0, 3))
    assert sorted(os.listdir(folder)) == ["samples-0001.csv"]       # the lock goes with its writer
    assert len(read_replay_log(folder / "samples-0001.csv")) == 3


def test_a_second_process_is_refused_and_the_first_keeps_writing(tmp_path):
    folder = tmp_path / "a"
    p = _holder(folder)
    try:
        with pytest.raises(FogmonError, match=rf"another fogmon \(pid {p.pid} on "):
            Archive(str(folder), FakeSource())
        assert os.path.isdir(folder)                                  # the refused writer removed nothing
    finally:
        p.communicate("", timeout=60)
    assert p.returncode == 0 and not os.path.exists(folder)          # nothing came: the holder's empty folder goes


def test_the_lock_of_a_writer_that_died_is_free(tmp_path):
    folder = tmp_path / "a"
    p = _holder(folder)
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=60)
    assert os.listdir(folder) == [LOCK]                               # left behind, with the dead pid
    with Archive(str(folder), FakeSource()) as a:                     # free: the kernel released it
        a.write(_block(0, 2))
    assert sorted(os.listdir(folder)) == ["samples-0001.csv"]


def test_the_lock_is_taken_before_the_check_and_kept_by_a_refused_folder(tmp_path):
    with Archive(str(tmp_path / "a"), FakeSource()) as a:
        a.write(_block(0, 3))
    with pytest.raises(FogmonError, match="already holds an archive"):
        Archive(str(tmp_path / "a"), FakeSource())
    assert LOCK not in os.listdir(tmp_path / "a")                     # a refused writer leaves no lock
