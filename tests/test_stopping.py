"""fogmon.stopping: SIGTERM and SIGHUP act as Ctrl-C; a shielded section finishes before
the interrupt; once the outputs are being closed, signals are only noted."""
import signal

import pytest

from fogmon import stopping


@pytest.mark.parametrize("sig, name, code", [(signal.SIGTERM, "SIGTERM", 143), (signal.SIGHUP, "SIGHUP", 129),
                                             (signal.SIGINT, "Ctrl-C", 130)])
def test_a_stop_signal_interrupts_like_ctrl_c(sig, name, code):
    with stopping.installed():
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(sig)
        assert stopping.stop_name() == name and stopping.interrupted_exit_code() == code
    assert signal.getsignal(sig) is not stopping._handler          # restored afterwards


def test_a_shielded_section_finishes_first_and_closing_only_notes():
    done = []
    with stopping.installed():
        with pytest.raises(KeyboardInterrupt), stopping.shielded():
            signal.raise_signal(signal.SIGTERM)
            done.append("rest of the block")
        assert done == ["rest of the block"]
    with stopping.installed():
        stopping.closing()
        signal.raise_signal(signal.SIGTERM)                          # noted, not raised
        signal.raise_signal(signal.SIGINT)                           # a second one: "already stopping"
        assert stopping.stop_requested() and stopping.stop_name() == "SIGTERM"
