"""StreamingDadev equals the batch engine at every window, in any block sizes, and does
not drift."""
import copy
import dataclasses
import pickle
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from fogmon.block import Block
from fogmon.davar.batch import adev_edf, dadev, oadev
from fogmon.davar.streaming import StreamingDadev

FS = 10.0


def rate(n, seed, bias=1000.0):
    rng = np.random.default_rng(seed)
    return bias + rng.normal(size=n) * 0.3 + np.cumsum(rng.normal(size=n)) * 0.002


def stream(engine, y, valid, seed):
    """Push y in random block sizes including 1; concatenate the emitted windows."""
    rng = np.random.default_rng(seed)
    out, i = [], 0
    while i < len(y):
        b = int(rng.choice([1, 1, 2, 17, 999, 4096]))
        out.append(engine.push(y[i:i + b], None if valid is None else valid[i:i + b]))
        i += b
    return {k: np.concatenate([getattr(r, k) for r in out]) for k in
            ("t_s", "end_index", "adev_dph", "lo_dph", "hi_dph", "edf", "n_terms")}


@pytest.mark.parametrize("hop_s,reanchor", [(None, None), (7.3, 2100), (0.1, 1500)])
def test_streaming_equals_batch_at_every_window(hop_s, reanchor):
    n = 30000
    y = rate(n, 1)
    valid = np.random.default_rng(5).random(n) > 0.0005
    valid[12000:12025] = False
    batch = dadev(y, FS, 100.0, hop_s, valid=valid, taus=5)
    engine = StreamingDadev(FS, 100.0, taus=5, hop_s=hop_s, reanchor=reanchor)
    got = stream(engine, y, valid, seed=7)
    assert engine.n_pushed == n
    assert np.array_equal(got["end_index"], batch.end_index)
    assert np.allclose(got["t_s"], batch.t_s, rtol=0, atol=1e-9)
    assert np.array_equal(got["n_terms"], batch.n_terms)
    for k in ("adev_dph", "lo_dph", "hi_dph", "edf"):
        ref = getattr(batch, k)
        assert np.array_equal(np.isnan(got[k]), np.isnan(ref))
        ok = ~np.isnan(ref)
        assert np.max(np.abs(got[k][ok] / ref[ok] - 1)) <= 1e-9, k


@pytest.mark.parametrize("hop", [97, 37])  # recorded sums, running sums
def test_huge_glitches_and_gaps_leave_no_residue_in_any_window(hop):
    """1e6 deg/h glitches enter and leave a 2^16 window (running sums: the plain SIMD path
    must hand over to exact recomputes; recorded sums: the cumulative sum carries them);
    every emitted window still equals the batch engine."""
    n, w = 300000, 2**16
    y = rate(n, 9)
    valid = np.ones(n, bool)
    valid[n - w // 2:n - w // 2 + 7] = False
    y[[150000, n - w - 10, n - 100]] += 1e6
    engine = StreamingDadev(1.0, w, hop_s=hop, alpha=0)
    got = stream(engine, y, valid, seed=3)
    ref = dadev(y, 1.0, w, hop, valid=valid, alpha=0)
    assert np.array_equal(got["n_terms"], ref.n_terms)
    assert np.nanmax(np.abs(got["adev_dph"] / ref.adev_dph - 1)) <= 1e-9
    cur = engine.current()
    assert np.max(np.abs(cur.adev_dph / oadev(y[-w:], 1.0, valid=valid[-w:]).adev_dph - 1)) <= 1e-9


def test_hop_1_counts_are_one_row_in_a_block_where_none_changes():
    """At hop 1 a block in which no window's valid-term counts differ returns them as one
    read-only row broadcast (no count written per window); a gap, a huge sample and a
    large glitch whose leaving forces exact recomputes (the counts stay) give every
    window its own counts and sums, equal to the batch engine."""
    n, w = 40000, 4096
    y = rate(n, 11)
    valid = np.ones(n, bool)
    valid[21000] = False
    y[30000:30010] += 3e7
    y[36000] = 1e9
    engine = StreamingDadev(1.0, w, taus=12, hop_s=1, alpha=0, reanchor=6000)
    blocks = [engine.push(y[i:i + 5000], valid[i:i + 5000]) for i in range(0, n, 5000)]
    ref = dadev(y, 1.0, w, 1, valid=valid, taus=12, alpha=0)
    assert np.array_equal(np.concatenate([b.n_terms for b in blocks]), ref.n_terms)
    got = np.concatenate([b.adev_dph for b in blocks])
    assert np.array_equal(np.isinf(got), np.isinf(ref.adev_dph)) and np.isinf(got).any()
    ok = np.isfinite(ref.adev_dph)
    assert np.max(np.abs(got[ok] / ref.adev_dph[ok] - 1)) <= 1e-9
    # the gap's windows end in blocks 4-5, the huge sample's from block 7 (its terms are
    # counted apart, so the engine writes that block's counts)
    assert [b.n_terms.strides[0] == 0 for b in blocks] == [True] * 4 + [False, False, True, False]


@pytest.mark.parametrize("hop", [1, 5])
def test_fixed_alpha_push_statistics_equal_batch_at_small_hops(hop):
    """With a fixed alpha at running-sum hops adev, bounds, EDF and counts equal the
    batch engine's, through gaps (a short one, and one longer than the blocks, whose
    windows keep the same reduced counts), a huge sample, and a large glitch whose
    leaving forces exact recomputes; adev equals the engine's own sums (``advance``,
    the same blocks)."""
    n, w = 30000, 2048
    y = rate(n, 13)
    valid = np.ones(n, bool)
    valid[6000:6003] = False
    valid[12000:12100] = False
    y[17000] += 3e7
    y[24000] = np.inf
    engine = StreamingDadev(1.0, w, taus=12, hop_s=hop, alpha=-1)
    got = stream(engine, y, valid, seed=4)
    ref = dadev(y, 1.0, w, hop, valid=valid, taus=12, alpha=-1)
    assert np.array_equal(got["n_terms"], ref.n_terms)
    for k in ("adev_dph", "lo_dph", "hi_dph", "edf"):
        want = getattr(ref, k)
        assert np.array_equal(np.isnan(got[k]), np.isnan(want)) and np.array_equal(np.isinf(got[k]), np.isinf(want))
        ok = np.isfinite(want)
        assert np.max(np.abs(got[k][ok] / want[ok] - 1)) <= 1e-9, k
    assert np.isinf(got["adev_dph"]).any() and (got["n_terms"] < ref.n_terms.max(axis=0)).any()
    fused, plain = (StreamingDadev(1.0, w, taus=12, hop_s=hop, alpha=-1) for _ in range(2))
    adev = np.concatenate([fused.push(y[i:i + 4096], valid[i:i + 4096]).adev_dph for i in range(0, n, 4096)])
    sums, counts = (np.concatenate(x) for x in zip(*[plain.advance(y[i:i + 4096], valid[i:i + 4096])[1:]
                                                     for i in range(0, n, 4096)], strict=True))
    assert adev.tobytes() == adev_edf(sums, counts, fused.m, w, -1)[0].tobytes()


@pytest.mark.parametrize("hop,alpha", [(1, 0), (3, None), (64, 0), (100, None)])
def test_push_forms_adev_when_read_bit_identical_to_the_eager_statistics(hop, alpha):
    """A push's ``adev_dph`` is formed from its windows' sums when first read
    (result.WindowSums): bit-identical to ``adev_edf``'s adev of the same sums (formed
    at once, as the push did before), through gaps, huge samples (+inf windows) and a
    large glitch; so are the EDF, the counts and the interval. ``window(i)`` forms row i
    alone, the same values, before and after the full read (which forms adev in place of
    the sums); a result pickled, copied (sharing the sums: also read by four threads at
    once) or rebuilt by ``dataclasses.replace`` before it was read reads the same;
    ``replace`` with an adev_dph array keeps it."""
    n, w = 12000, 1024
    y = rate(n, 21)
    valid = np.ones(n, bool)
    valid[3000:3002] = False
    valid[5000:5400] = False
    y[7000] += 3e7
    y[8000] = np.inf
    y[9500] = 5e9
    lazy, plain = (StreamingDadev(1.0, w, taus=10, hop_s=hop, alpha=alpha) for _ in range(2))
    checked = 0
    for i in range(0, n, 1500):
        res = lazy.push(y[i:i + 1500], valid[i:i + 1500])
        ends, sums, counts = plain.advance(y[i:i + 1500], valid[i:i + 1500])
        if not len(res):
            continue
        again = pickle.loads(pickle.dumps(res))
        twin = copy.copy(res)
        moved = dataclasses.replace(res, hop_s=res.hop_s)
        rows = range(0, len(res), max(1, len(res) // 7))
        wins = [res.window(r) for r in rows]  # before adev_dph is read: each row alone
        # (adev does not depend on the EDF: alpha=None's quick fits are checked elsewhere)
        adev, edf = adev_edf(sums, counts, res.m, w, 0 if alpha is None else alpha)
        if i == 1500 * 4:  # copies sharing this block's sums read by four threads at once
            start = threading.Barrier(4)

            def read(r, start=start):
                start.wait()
                return r.adev_dph.tobytes()
            with ThreadPoolExecutor(4) as pool:
                assert set(pool.map(read, [copy.copy(res) for _ in range(4)])) == {adev.tobytes()}
        for got in (res, twin, again, moved):
            assert got.adev_dph.tobytes() == adev.tobytes()
        assert np.array_equal(res.n_terms, counts) and np.array_equal(res.end_index, ends)
        if alpha is not None:
            assert np.array_equal(res.edf, edf, equal_nan=True)
        for r, win in zip(rows, wins, strict=True):
            assert win.adev_dph.tobytes() == adev[r].tobytes() == twin.window(r).adev_dph.tobytes()
            for k in ("lo_dph", "hi_dph"):  # (a NaN's sign may differ: a NaN row times its factors)
                assert np.array_equal(getattr(win, k), getattr(res, k)[r], equal_nan=True)
        checked += np.isinf(adev).any() + (counts < w - 2 * res.m + 1).any()
    assert checked >= 2  # windows with +inf and with gaps were among them
    kept = dataclasses.replace(res, adev_dph=np.zeros_like(adev))
    assert not kept.adev_dph.any() and not kept.window(0).adev_dph.any()


def test_hop_longer_than_the_window():
    n = 20000
    y = rate(n, 4)
    batch = dadev(y, FS, 100.0, 130.0, taus=5)
    got = stream(StreamingDadev(FS, 100.0, taus=5, hop_s=130.0), y, None, seed=2)
    assert np.array_equal(got["end_index"], batch.end_index) and len(batch.end_index) == 15
    assert np.array_equal(got["n_terms"], batch.n_terms)
    assert np.max(np.abs(got["adev_dph"] / batch.adev_dph - 1)) <= 1e-9


def test_current_is_the_last_window_and_the_filling_window():
    y = rate(5000, 2)
    engine = StreamingDadev(FS, 200.0, hop_s=50.0)
    engine.push(y[:700])
    cur = engine.current()  # window still filling: 700 samples
    ref = oadev(y[:700], FS, taus=cur.tau_s)  # batch stops at m <= 700 // 4
    assert cur.n_samples == 700
    ok = cur.m <= 175
    assert np.array_equal(cur.n_terms[~ok], [189])  # m = 256 (<= 2000 // 4) already has terms
    assert np.array_equal(cur.n_terms[ok], ref.n_terms)
    assert np.max(np.abs(cur.adev_dph[ok] / ref.adev_dph - 1)) <= 1e-9
    engine.push(y[700:])
    cur = engine.current()
    ref = oadev(y[-2000:], FS)
    assert np.array_equal(cur.n_terms, ref.n_terms)
    assert np.max(np.abs(cur.adev_dph / ref.adev_dph - 1)) <= 1e-9
    # a window's bounds are the windows' (the batch dadev's), not a whole record's (oadev's mixture rules)
    win = dadev(y[-2000:], FS, 200.0)
    assert np.max(np.abs(cur.lo_dph / win.lo_dph[-1] - 1)) <= 1e-9


def test_push_accepts_blocks():
    y = rate(3000, 8)
    valid = np.ones(3000, bool)
    valid[100] = False
    a = StreamingDadev(FS, 100.0, hop_s=10.0).push(Block.make(np.arange(3000) / FS, y, valid))
    b = StreamingDadev(FS, 100.0, hop_s=10.0).push(y, valid)
    assert len(a) == 21 and np.array_equal(a.adev_dph, b.adev_dph) and np.array_equal(a.n_terms, b.n_terms)


def test_empty_push_and_no_window_yet():
    engine = StreamingDadev(FS, 100.0)
    r = engine.push(np.zeros(0))
    assert r.adev_dph.shape == (0, len(engine.m)) and engine.n_pushed == 0
    r = engine.push(rate(500, 3))
    assert len(r) == 0
    r = engine.push(rate(500, 4))
    assert r.end_index.tolist() == [999]


@pytest.mark.parametrize("hop", [2**14, 32])  # recorded sums, running sums
def test_no_drift_over_1e6_samples_with_a_1000_dph_bias(hop):
    """2^20 samples, 1000 deg/h bias, 2^14 window: the last emitted window equals an exact
    recompute to 1e-9 (validation/davar_drift.py runs 1e8 samples)."""
    n, w = 2**20, 2**14
    y = rate(n, 6)
    y[300000] += 1e6  # a huge glitch enters and leaves the window: no cancellation residue
    engine = StreamingDadev(1.0, w, taus="octave", hop_s=hop)
    for i in range(0, n, 65536):
        ends, sums, counts = engine.advance(y[i:i + 65536])
    assert ends[-1] == n - 1
    ref = oadev(y[-w:], 1.0)
    assert np.array_equal(counts[-1], ref.n_terms)
    assert np.max(np.abs(np.sqrt(sums[-1] / (2 * counts[-1])) / ref.adev_dph - 1)) <= 1e-9


def test_random_configurations_equal_batch():
    """Random window, hop (both modes, and hops longer than the window), re-anchor
    interval, taus, gaps, 1e6 deg/h glitches and block sizes: every emitted window's sum
    and count equal the batch engine's. (Found a running-sum residue: a glitch term
    entering as t / m and leaving as t * (1 / m).)"""
    rng = np.random.default_rng(123)
    for _ in range(60):
        w = int(rng.integers(40, 1500))
        hop = int(rng.integers(1, 3 * w))
        n = int(rng.integers(w, 5 * w + 10))
        y = 50 + rng.normal(size=n) + np.cumsum(rng.normal(size=n)) * 0.01
        valid = rng.random(n) > rng.choice([0, 0.001, 0.05])
        if rng.random() < 0.5:
            y[rng.integers(0, n, 3)] += 1e6
        reanchor = int(rng.integers(w // 2 + 1, 3 * w)) if rng.random() < 0.5 else None
        engine = StreamingDadev(1.0, w, taus=int(rng.integers(2, 8)), hop_s=hop, alpha=0, reanchor=reanchor)
        out, i = [], 0
        while i < n:
            b = int(rng.choice([1, 3, 64, 1000, 5000]))
            out.append(engine.advance(y[i:i + b], valid[i:i + b]))
            i += b
        ends, sums, counts = (np.concatenate([o[j] for o in out]) for j in range(3))
        ref = dadev(y, 1.0, w, hop, taus=engine.m.astype(float), valid=valid, alpha=0)
        assert np.array_equal(ends, ref.end_index) and np.array_equal(counts, ref.n_terms)
        ok = counts > 0
        ref_sums = 2.0 * counts[ok] * ref.adev_dph[ok] ** 2
        assert np.max(np.abs(sums[ok] / ref_sums - 1), initial=0.0) <= 1e-9, (w, hop, n)
