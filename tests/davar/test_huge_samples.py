"""No single sample, however large, changes a window that does not hold it: streaming
(recorded and running sums, blocks of 1 and 8192) and batch, against the same windows of
the record without it; windows holding a huge sample (|rate| > 1e8 deg/h or infinite)
report +inf, those holding a large finite one stay finite."""
import numpy as np
import pytest

from fogmon.davar.batch import dadev, oadev
from fogmon.davar.kernels import CEILING_DPH
from fogmon.davar.streaming import StreamingDadev

N, W = 6000, 1024
VALUES = (1e30, 1e160, 1e300, np.inf, np.finfo(float).max, -1e300, -np.inf, 3e7)
POSITIONS = (0, 2047, 5990)  # first sample, inside the kept window at the first re-anchor, near the end


def record():
    rng = np.random.default_rng(11)
    y = 1000.0 + rng.normal(size=N) * 0.3 + np.cumsum(rng.normal(size=N)) * 0.002
    valid = np.ones(N, bool)
    valid[3100:3104] = False  # a gap too
    return y, valid


def stream(y, valid, hop, block):
    eng = StreamingDadev(1.0, W, taus="octave", hop_s=hop, alpha=0, reanchor=1500)
    out = [eng.advance(y[i:i + block], valid[i:i + block]) for i in range(0, len(y), block)]
    ends, sums, counts = (np.concatenate(x) for x in zip(*out, strict=True))
    with np.errstate(invalid="ignore", divide="ignore"):
        return ends, np.sqrt(sums / (2.0 * counts)), counts, eng.current()


def check(ends, adev, counts, ref_adev, ref_counts, pos, value):
    """Same term counts as the reference; windows without ``pos`` equal it to 1e-12
    (NaN only where it has no term: a gap). Windows with it: for a huge value +inf at
    every tau where a counted term spans it (all but the taus whose terms spanning it
    all span the gap too, which equal the reference), for a large finite one finite."""
    assert np.array_equal(counts, ref_counts)
    holds = (ends - W + 1 <= pos) & (pos <= ends)
    assert np.array_equal(np.isnan(adev), np.isnan(ref_adev))
    with np.errstate(invalid="ignore"):
        rel = np.abs(adev / ref_adev - 1)
    assert np.nanmax(rel[~holds], initial=0.0) <= 1e-12
    inside, rel_inside = adev[holds], rel[holds]
    if abs(value) > CEILING_DPH:
        assert np.all(inside[:, 0] == np.inf)  # m = 1: the two terms holding pos
        assert np.all((inside == np.inf) | (rel_inside <= 1e-12) | np.isnan(inside))
    else:
        assert np.all(np.isfinite(inside) | np.isnan(ref_adev[holds]))
    return holds


@pytest.mark.parametrize("hop,block", [(64, 1), (1, 1), (64, 8192), (250, 8192), (1, 8192), (13, 8192)])
def test_streaming_windows_without_the_sample_are_untouched(hop, block):
    """Recorded sums (hop >= 64) and running sums, in blocks of 1 and 8192."""
    y0, valid = record()
    ends, ref_adev, ref_counts, ref_cur = stream(y0, valid, hop, block)
    for value in VALUES:
        for pos in POSITIONS:
            y = y0.copy()
            y[pos] = value
            e, adev, counts, cur = stream(y, valid, hop, block)
            assert np.array_equal(e, ends)
            holds = check(e, adev, counts, ref_adev, ref_counts, pos, value)
            assert (holds.any() or pos > e[-1]) and not holds.all()
            if pos >= N - W:  # the current window holds it
                assert np.all(cur.adev_dph == np.inf) if abs(value) > CEILING_DPH else np.all(
                    np.isfinite(cur.adev_dph))
            else:
                assert np.max(np.abs(cur.adev_dph / ref_cur.adev_dph - 1)) <= 1e-12
            assert np.array_equal(cur.n_terms, ref_cur.n_terms)


@pytest.mark.parametrize("hop", [1, 64, 333])
def test_batch_windows_without_the_sample_are_untouched(hop):
    y0, valid = record()
    ref = dadev(y0, 1.0, W, hop, valid=valid, alpha=0)
    for value in VALUES:
        for pos in POSITIONS + (3000,):
            y = y0.copy()
            y[pos] = value
            d = dadev(y, 1.0, W, hop, valid=valid, alpha=0)
            check(d.end_index, d.adev_dph, d.n_terms, ref.adev_dph, ref.n_terms, pos, value)
            whole = oadev(y, 1.0, valid=valid, alpha=0)
            assert not np.isnan(whole.adev_dph).any() and not np.isnan(whole.lo_dph).any()


def test_a_1e30_sample_no_longer_zeroes_every_later_window():
    """The issue's report: after one 1e30 deg/h sample the recorded-sum engine gave
    ADEV = 0 at every tau in every later window (NaN after 1e160), forever."""
    rng = np.random.default_rng(2)
    clean = 1000.0 + rng.normal(size=40 * W)
    y = clean.copy()
    y[100] = 1e30
    y[25 * W] = 1e160
    eng, ref = (StreamingDadev(1.0, W, hop_s=W // 4, alpha=0) for _ in range(2))
    got = [eng.push(y[:20 * W]), eng.push(y[20 * W:])]
    want = [ref.push(clean[:20 * W]), ref.push(clean[20 * W:])]
    holds = [(r.end_index >= p) & (r.end_index - W + 1 <= p) for r in got for p in (100, 25 * W)]
    for g, r, h in zip(got, want, (holds[0] | holds[1], holds[2] | holds[3]), strict=True):
        assert np.all(g.adev_dph[h] == np.inf) and h.sum() == (1 if g is got[0] else 4)
        assert np.max(np.abs(g.adev_dph[~h] / r.adev_dph[~h] - 1)) <= 1e-12
        assert not np.isnan(g.adev_dph).any() and not np.isnan(g.lo_dph).any()


@pytest.mark.parametrize("hop", [64, 1])
def test_a_large_first_sample_does_not_spoil_the_reference_level(hop):
    """A 3e7 deg/h glitch pushed alone as the very first sample sets no lasting
    reference level (early re-reference while the first window fills): windows without
    it equal those of the record without it."""
    y0, valid = record()
    _, ref_adev, _, _ = stream(y0, valid, hop, 8192)
    y = y0.copy()
    y[0] = 3e7
    eng = StreamingDadev(1.0, W, taus="octave", hop_s=hop, alpha=0)
    eng.advance(y[:1], valid[:1])
    for i in range(1, 300):  # one by one past the early re-reference (after W / 8 samples)
        eng.advance(y[i:i + 1], valid[i:i + 1])
    assert abs(eng._ref - 1000.0) < 10.0
    ends, sums, counts = eng.advance(y[300:], valid[300:])
    with np.errstate(invalid="ignore"):
        adev = np.sqrt(sums / (2.0 * counts))
    later = ends >= W
    assert np.array_equal(np.isnan(adev[later]), np.isnan(ref_adev[later]))  # NaN: no term (the gap)
    assert np.nanmax(np.abs(adev[later] / ref_adev[later] - 1)) <= 1e-12


@pytest.mark.parametrize("hop", [64, 7])
def test_a_signal_swinging_far_beyond_the_large_threshold_equals_batch(hop):
    """Every sample large (a rate table at +-1e6 deg/h), with a gap and a huge sample:
    the streaming engine (side prefix, vectorised large-sample path) equals the batch
    engine at every window."""
    n = 9000
    rng = np.random.default_rng(4)
    y = 1e6 * np.sin(2 * np.pi * np.arange(n) / 3000.0) + rng.normal(size=n)
    valid = np.ones(n, bool)
    valid[4000:4003] = False
    y[6500] = 1e300
    ref = dadev(y, 1.0, W, hop, valid=valid, alpha=0)
    e, adev, counts, _ = stream(y, valid, hop, 1000)
    assert np.array_equal(e, ref.end_index) and np.array_equal(counts, ref.n_terms)
    assert np.array_equal(adev == np.inf, ref.adev_dph == np.inf) and (adev == np.inf).any()
    fin = np.isfinite(ref.adev_dph)
    assert np.max(np.abs(adev[fin] / ref.adev_dph[fin] - 1)) <= 1e-9
