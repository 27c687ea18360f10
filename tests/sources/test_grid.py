"""Sample grid: counter jumps and outages become invalid placeholders, never joined;
the host clock finds whole counter wraps; implausible gaps are no placeholders."""
import math

import numpy as np
import pytest

from fogmon.errors import FogmonError
from fogmon.sources.frames import Frames
from fogmon.sources.grid import (
    CLOCK_CONFIRM_S,
    HOST_CLOCK,
    IMPLAUSIBLE,
    MAX_GAP_SAMPLES,
    GridAssembler,
    Placed,
    gap_limit,
)


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
    assert g.counters == {"seq_gaps": 2, "samples_missing": 8, "invalid_samples": 0, "implausible_gaps": 0,
                          "clock_wraps": 0}
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


# -- the host clock finds whole counter wraps (rule 3) ------------------------------------
FS = 1000.0


def looks(g, seqs, t_of_k, lost=(), chunk=100, jitter_s=None):
    """Push frames k = 0, 1, ... (counter k % 128; those in ``lost`` vanish without a byte
    gap) in chunks of ``chunk`` frames, each followed by a look at the host clock at the
    time the chunk's last frame was sent (``t_of_k``) plus ``jitter_s(i)``; the blocks."""
    blocks, ks = [], [k for k in seqs if k not in set(lost)]
    for i in range(0, len(ks), chunk):
        part = ks[i:i + chunk]
        blocks.append(g.push(Frames.from_lists([k % 128 for k in part], [float(k) for k in part], [True] * len(part))))
        g.observe_clock(t_of_k(part[-1]) + (jitter_s(i // chunk) if jitter_s else 0.0))
    return blocks


def placed_k(blocks):
    """Frame k of each valid sample, and its grid index."""
    rate = np.concatenate([b.rate_dph for b in blocks])
    idx = np.flatnonzero(np.isfinite(rate))
    return rate[idx].astype(int), idx


def test_whole_wraps_lost_without_a_byte_gap_are_placed_by_the_host_clock():
    """256 frames (two counter wraps) vanish at a frame boundary: the counter sees nothing;
    the host clock does, within CLOCK_CONFIRM_S, and every later sample is back on its slot."""
    g = GridAssembler(FS, 128)
    lost = range(1000, 1256)
    blocks = looks(g, range(4000), lambda k: k / FS + 0.003, lost)
    k, idx = placed_k(blocks)
    late = k > 1256 + 1000 * CLOCK_CONFIRM_S + 200
    assert np.array_equal(idx[late], k[late])                       # on the right slot again
    assert g.counters["clock_wraps"] == 2 and g.counters["samples_missing"] == 256
    (ev,) = [e for b in blocks for e in b.events if e.kind == "gap"]
    assert ev.message.startswith("256 sample(s) lost at t=") and "host clock: 2 whole counter wrap(s)" in ev.message
    assert "lost after t=1.000 s" in ev.message               # the last look before the loss
    early = (k >= 1256) & ~late
    assert np.all(idx[early] <= k[early]) and np.all(idx[early] >= k[early] - 256)


def test_late_reads_and_a_slow_device_clock_place_no_wrap():
    """Reads late by up to 60 ms (half a wrap is 64 ms), one read 0.5 s late, and a device
    clock 500 ppm slow over 200 s: no wrap is inferred, nothing is placed."""
    g = GridAssembler(FS, 128)
    rng = np.random.default_rng(3)
    late = rng.uniform(0.0, 0.06, 2000)
    late[700] = 0.5
    looks(g, range(200_000), lambda k: k / (FS * (1 - 5e-4)), jitter_s=lambda i: late[i])
    assert g.counters["clock_wraps"] == 0 and g.counters["samples_missing"] == 0


def test_a_device_that_sends_late_and_catches_up_places_no_wrap():
    """The device holds its frames for 2 s, then sends them as fast as a pty takes them
    (555 frames per read every 0.1 s): the grid is up to 2 s behind the host clock, but
    less at every look as it catches up, so no wrap is placed; then it loses 256 frames
    for good, and the clock places exactly those."""
    g = GridAssembler(FS, 128)
    k = 0
    for wake in range(1, 200):
        t = wake / 10
        due = int(t * FS) if not 5.0 <= t < 7.0 else 5000
        part = list(range(k, min(due, k + 555)))
        k += len(part)
        part = [x for x in part if not 15_000 <= x < 15_256]
        if part:
            g.push(Frames.from_lists([x % 128 for x in part], [float(x) for x in part], [True] * len(part)))
            g.observe_clock(t)
    assert g.counters["clock_wraps"] == 2 and g.counters["samples_missing"] == 256


def test_a_device_slower_than_its_rate_is_no_loss_but_a_loss_on_top_of_it_is():
    """The device runs 1 % slower than ``sample_rate_hz`` (ten times the drift allowed):
    the grid falls behind the clock gradually, never by a step, so nothing is placed for
    it; 128 frames lost at once on top of it are one wrap, exactly."""
    g = GridAssembler(FS, 128)
    looks(g, range(60_000), lambda k: k / (FS * 0.99), lost=range(30_000, 30_128))
    assert g.counters["clock_wraps"] == 1 and g.counters["samples_missing"] == 128


def test_the_clock_decision_replays_from_the_sidecar_record():
    """What the clock decided (grid.decisions) placed again by ``place`` on a grid without
    a clock gives the same samples and counters."""
    g = GridAssembler(FS, 128)
    decided, blocks = [], []
    ks = [k for k in range(3000) if not 500 <= k < 628]
    for i in range(0, len(ks), 100):
        part = ks[i:i + 100]
        blocks.append(g.push(Frames.from_lists([k % 128 for k in part], [float(k) for k in part],
                                                [True] * len(part))))
        decided += [(i, p) for p in g.decisions]
        g.observe_clock(part[-1] / FS)
    assert [p for _, p in decided] == [Placed(0, 128, HOST_CLOCK, 1)]
    r = GridAssembler(FS, 128)
    at = decided[0][0]
    r.push(Frames.from_lists([k % 128 for k in ks[:at]], [float(k) for k in ks[:at]], [True] * at))
    r.place(decided[0][1])
    rest = ks[at:]
    r.push(Frames.from_lists([k % 128 for k in rest], [float(k) for k in rest], [True] * len(rest)))
    assert r.counters == g.counters and r.next_index == g.next_index


# -- plausible gaps only --------------------------------------------------------------------
def test_a_counter_reset_is_no_gap_and_allocates_nothing():
    """An unbounded counter (``lines`` with ``seq``) that restarts at 0, and one that jumps
    by 10**15: no placeholder, an implausible event each, counted; a true jump of 3 stays."""
    g = GridAssembler(100.0, 2**62)
    b = g.push(Frames.from_lists([5000, 5001, 0, 1, 10**15, 10**15 + 4], [1.0] * 6, [True] * 6))
    assert len(b) == 9 and g.counters["implausible_gaps"] == 2 and g.counters["samples_missing"] == 3
    msgs = [e.message for e in b.events if e.kind == "implausible"]
    assert msgs[0].startswith("the sequence counter went from 5001 to 0 at t=0.020000 s")
    assert "from 1 to 1000000000000000" in msgs[1]


def test_the_clock_bounds_a_counter_jump_and_records_what_it_decided():
    """A live source's clock allows 1 s: a jump of 10,000 samples at 1 kHz is implausible
    there (though the default limit of an hour would place it), and the decision is
    recorded for the replay."""
    g = GridAssembler(FS, 2**62)
    g.push(Frames.from_lists([0, 1], [1.0, 1.0], [True, True]))
    g.max_gap = gap_limit(FS, 1.0, 2**62)
    b = g.push(Frames.from_lists([10_002, 10_003], [1.0, 1.0], [True, True]))
    assert len(b) == 2 and g.counters["implausible_gaps"] == 1
    assert g.decisions == [Placed(0, 0, IMPLAUSIBLE)]
    g.max_gap = None
    b = g.push(Frames.from_lists([20_004], [1.0], [True]))
    assert len(b) == 10_001 and g.decisions == []


def test_an_outage_beyond_any_gap_is_an_error_and_sample_rates_are_bounded():
    g = GridAssembler(FS, 128)
    g.push(frames([0, 1]))
    with pytest.raises(FogmonError, match="an outage of 1e[+]12 samples .* more than one gap"):
        g.mark_break(1e12)
    with pytest.raises(FogmonError):
        g.mark_break(math.nan)
    with pytest.raises(FogmonError, match="sample_rate_hz must be > 0 and at most 1,000,000 Hz, got 1e[+]12"):
        GridAssembler(1e12, None)
    assert gap_limit(FS, 2.0, 128) == 2129 and gap_limit(1e6, math.inf) == MAX_GAP_SAMPLES + 1


def test_a_long_silence_the_clock_vouches_for_replays_the_same():
    """A ``lines`` board with an unbounded counter falls silent for 2 h and comes back
    counting on: live, its clock vouches for the 2 h (placed, though more than a gap
    without a clock may hold), and that decision replays the same."""
    live = GridAssembler(10.0, 2**62)
    live.push(Frames.from_lists([0, 1], [1.0, 1.0], [True, True]))
    live.max_gap = gap_limit(10.0, 7201.0, 2**62)
    b = live.push(Frames.from_lists([72_002], [1.0], [True]))
    assert len(b) == 72_001 and live.counters["implausible_gaps"] == 0
    assert live.decisions == [Placed(0, 72_000, 0)]
    replay = GridAssembler(10.0, 2**62)
    replay.push(Frames.from_lists([0, 1], [1.0, 1.0], [True, True]))
    replay.place(live.decisions[0])
    assert len(replay.push(Frames.from_lists([72_002], [1.0], [True]))) == 72_001
    assert replay.counters == live.counters
    alone = GridAssembler(10.0, 2**62)            # without the record: more than a gap may hold
    alone.push(Frames.from_lists([0, 1], [1.0, 1.0], [True, True]))
    assert len(alone.push(Frames.from_lists([72_002], [1.0], [True]))) == 1
