"""What the test modules share (tests/ is on sys.path: pyproject.toml's pytest
``pythonpath``): ``doubles`` (a source of pre-made blocks, a collecting sink, white
noise, source options from a command line), ``fake_device`` (fake serial gyros on a
pty) and ``fake_kvh`` (a 1 kHz KVH DSP-1760 on a pty, run as a program), ``can_gyro``
(the example DBC's gyro frames), ``recordings`` (other tools' recordings written with
their own libraries), ``rrd`` (an .rrd read back), ``net`` (ports, listening sockets,
polling) and ``explain`` (the report invariants, an explain run). A test module
imports these, never another test module."""
from __future__ import annotations

from pathlib import Path

#: the repository's root folder (replay_logs/, validation/, fogmon/data/ are under it)
REPO = Path(__file__).resolve().parents[2]
#: the test data (tests/data/)
DATA = REPO / "tests" / "data"
