"""fogmon.startup: the collector paused over loading phases, in the program's own process only."""
import gc
import subprocess
import sys

import pytest

from fogmon import startup


@pytest.fixture
def unfrozen():
    yield
    gc.unfreeze()     # what a phase froze goes back to the collector


def test_a_program_that_imports_fogmon_keeps_its_collector(unfrozen):
    frozen = gc.get_freeze_count()
    with startup.loading():
        assert gc.isenabled()
    assert gc.isenabled() and gc.get_freeze_count() == frozen


def test_the_programs_own_phases_pause_then_freeze(monkeypatch, unfrozen):
    monkeypatch.setattr(startup, "_own_process", True)
    with startup.loading():
        assert not gc.isenabled()
        with startup.loading():
            assert not gc.isenabled()
        assert not gc.isenabled()      # the outer phase goes on
    assert gc.isenabled() and gc.get_freeze_count() > 0
    gc.disable()
    try:
        with startup.loading():
            pass
        assert not gc.isenabled()      # left as it was
    finally:
        gc.enable()


def test_the_programs_rerun_arrays_do_not_import_pandas():
    # in a fresh process: pandas may be imported in this one
    code = """
import sys
import numpy as np
from fogmon import startup
import fogmon.sinks.rerun.sink
from fogmon.sinks.rerun.blueprint import blueprint
startup.own_process()
startup.arrow_without_pandas()
import rerun as rr
blueprint(curve_bounds=((-1, 3), (-2, 1)))
rr.Scalars.columns(scalars=np.arange(3.0))
assert "pandas" not in sys.modules
import pandas as pd
import pyarrow as pa
t = pa.Table.from_pandas(pd.DataFrame({"c": pd.Categorical(["a", "b"])}))
assert pa.types.is_dictionary(t.schema.field("c").type)    # pandas users are served as always
"""
    subprocess.run([sys.executable, "-c", code], check=True)


def test_a_program_that_imports_fogmon_keeps_arrow_as_it_is():
    code = """
import sys
from fogmon import startup
startup.arrow_without_pandas()
assert "pyarrow" not in sys.modules and "pandas" not in sys.modules
"""
    subprocess.run([sys.executable, "-c", code], check=True)
