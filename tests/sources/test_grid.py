"""Sample grid: counter jumps and outages become invalid placeholders, never joined."""
import numpy as np

from fogmon.sources.frames import Frames
from fogmon.sources.grid import GridAssembler


def frames(seq, valid=None):
    seq = list(seq)
    return Frames.from_lists(seq, [float(s) for s in seq], valid if valid is not None else [True] * len(seq),
                             {"temp_c": [20.0] * len(seq)})


def test_counter_jumps_insert_placeholders_across_wraps_and_blocks():
    g = GridAssembler(100.0, 128, ("temp_c",))
    b1 = g.push(frames([125, 126, 127, 2, 3]))           # 0 and 1 lost across the wrap
    b2 = g.push(frames([10, 11]))                          # 4..9 lost between blocks
    assert len(b1) == 7 and len(b2) == 8
    np.testing.assert_array_equal(b1.valid, [1, 1, 1, 0, 0, 1, 1])
    assert np.isnan(b1.rate_dph[3:5]).all() and np.isnan(b1.aux["temp_c"][3:5]).all()
    np.testing.assert_allclose(np.concatenate([b1.t_s, b2.t_s]), np.arange(15) / 100.0)
    assert g.counters == {"seq_gaps": 2, "samples_missing": 8, "invalid_samples": 0}
    assert [e.kind for e in b1.events + b2.events] == ["gap", "gap"]
    assert b2.events[0].t_s == 0.07


def test_invalid_samples_are_nan_and_counted():
    g = GridAssembler(10.0, 128)
    b = g.push(Frames.from_lists([0, 1, 2], [1.0, 2.0, 3.0], [True, False, True]))
    assert list(b.valid) == [True, False, True] and np.isnan(b.rate_dph[1])
    assert g.counters["invalid_samples"] == 1


def test_outage_longer_than_a_wrap_is_resolved_by_the_clock():
    g = GridAssembler(100.0, 16)
    g.push(frames([0, 1, 2]))
    # 1.0 s outage: frames 3..102 lost, the next frame is k=103 (seq 103 % 16 = 7); the clock says ~100 lost
    g.mark_break(100.0 + 2.3)                # a clock estimate off by 2.3 samples
    b = g.push(frames([7, 8]))
    assert len(b) == 102 and g.counters["samples_missing"] == 100 and b.valid[-2:].all()


def test_outage_without_counter_uses_the_clock_estimate():
    g = GridAssembler(10.0, None)
    g.push(Frames.from_lists([-1, -1], [1.0, 1.0], [True, True]))
    g.mark_break(4.4)
    b = g.push(Frames.from_lists([-1], [1.0], [True]))
    assert len(b) == 5 and g.counters["samples_missing"] == 4
    b = g.push(Frames.from_lists([-1], [1.0], [True]))
    assert len(b) == 1


def test_stall_with_backlog_inserts_nothing():
    g = GridAssembler(100.0, 128)
    g.push(frames([0, 1]))
    g.mark_break(0.4)                        # reader stalled; the frames were buffered, none lost
    b = g.push(frames([2, 3]))
    assert len(b) == 2 and g.counters["samples_missing"] == 0
