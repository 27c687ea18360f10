"""The pipeline's reader queue is bounded: a source that can wait is held back
(back-pressure), a live device never is (its blocks are dropped, counted and replaced by
placeholders on the same grid). Tests synchronise on data and thread ends, never on time."""
import threading

import numpy as np

from fogmon.block import Block, Event
from fogmon.pipeline.axis import _Tail
from fogmon.pipeline.reader import _ThreadedBlocks

RATE_HZ = 10.0


class CountingSource:
    """Blocks of 10 samples on a 10 Hz grid; ``produced`` counts the blocks handed out;
    after ``pause_after`` blocks it sets ``paused`` and waits for ``resume``. ``live``:
    it stands for a device (fogmon.sources.base.Source.live)."""

    opened_s = None

    def __init__(self, n_blocks: int, pause_after: int | None = None, live: bool = False):
        self.sample_rate_hz, self.aux_names, self.axes, self.live = RATE_HZ, ("temp_c",), (), live
        self.n_blocks, self.pause_after = n_blocks, pause_after
        self.resume, self.paused = threading.Event(), threading.Event()
        self.produced = 0
        self.closed = False

    def blocks(self):
        for k in range(self.n_blocks):
            if k == self.pause_after:
                self.paused.set()
                self.resume.wait()
            if self.closed:
                return
            self.produced += 1
            t = (10 * k + np.arange(10)) / RATE_HZ
            yield Block.make(t, np.full(10, float(k)), aux={"temp_c": np.full(10, 20.0)},
                             events=(Event(float(t[0]), "gap", f"block {k}"),))

    def close(self):
        self.closed = True
        self.resume.set()

    def limit(self, n_samples):
        pass


def test_a_source_that_can_wait_is_held_back_when_the_queue_is_full():
    src = CountingSource(10)
    q = _ThreadedBlocks(src, max_samples=30)
    with q._cond:
        assert q._cond.wait_for(lambda: q.held_back >= 1, timeout=120)
        assert q._n == 30 and src.produced == 4      # 3 blocks queued, the 4th waits for room
    got = list(q)
    assert [b.rate_dph[0] for b in got] == list(range(10)) and q.counters == {}
    assert q.backlog() == []


def test_closing_releases_a_held_back_reader():
    src = CountingSource(100)
    q = _ThreadedBlocks(src, max_samples=20)
    with q._cond:
        assert q._cond.wait_for(lambda: q.held_back >= 1, timeout=120)
    src.close()
    q.backlog(timeout_s=120)                      # releases the waiting reader, which stops
    q._thread.join(120)
    assert not q._thread.is_alive() and src.produced < 100


def test_a_live_device_is_never_held_back_its_excess_is_dropped_and_reported():
    src = CountingSource(9, pause_after=6, live=True)
    q = _ThreadedBlocks(src, max_samples=30)
    assert src.paused.wait(timeout=120)           # blocks 0..5 read while nobody consumed
    it = iter(q)
    first = [next(it) for _ in range(4)]          # 3 queued blocks, then the placeholder for blocks 3..5
    assert [b.rate_dph[0] for b in first[:3]] == [0, 1, 2]
    ph = first[3]
    np.testing.assert_array_equal(ph.t_s, np.arange(30, 60) / RATE_HZ)   # same grid, no shift
    assert not ph.valid.any() and np.isnan(ph.aux["temp_c"]).all()
    assert [e.kind for e in ph.events] == ["dropped", "gap", "gap", "gap"]
    assert ph.events[0].message.startswith("30 samples (3 blocks) from t=3.000000 s dropped: processing fell "
                                           "more than 30 samples (3 s) behind the device")
    assert q.counters == {"blocks_dropped": 3, "samples_dropped": 30}
    src.resume.set()                              # the queue is empty again: 3 more blocks fit
    rest = list(it)
    assert [b.rate_dph[0] for b in rest] == [6, 7, 8] and q.counters["blocks_dropped"] == 3
    assert q.backlog() == []


def test_tail_keeps_exactly_the_latest_samples():
    rng = np.random.default_rng(0)
    parts = []
    for n in (10, 995, 1, 2500, 7, 999, 3):
        parts.append((rng.standard_normal(n), rng.standard_normal(n) > 0))
        tail = _Tail(1000)
        for r, v in parts:
            tail.push(r, v)
        got_r, got_v, _ = tail.take()
        np.testing.assert_array_equal(got_r, np.concatenate([p[0] for p in parts])[-1000:])
        np.testing.assert_array_equal(got_v, np.concatenate([p[1] for p in parts])[-1000:])
