"""fogmon.startup: the collector paused over loading phases, in the program's own process only."""
import gc

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
