"""Exactness of the fast paths of issue 13: one-sample pushes (staged) against block
pushes, the branch-free frame statistics against the per-entry definitions, the tiled
batch window sums against brute force, the held noise type against a refit, the model
test that holds it against its definition, and a numba cache in a read-only directory."""
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import chi2

from fogmon.block import Block
from fogmon.davar import window_stats
from fogmon.davar.batch import HOLD_Z, dadev, edf_rows, oadev, row_edf, statistics
from fogmon.davar.confidence import chi2_bounds, edf_effective, edf_full
from fogmon.davar.streaming import STAGE, StreamingDadev


def _record(n, seed=0):
    rng = np.random.default_rng(seed)
    y = 1000.0 + rng.normal(size=n) + np.cumsum(rng.normal(size=n)) * 0.01
    y[n * 3 // 7:n * 3 // 7 + 4] = np.nan
    y[n * 5 // 7] = 1e6  # large glitch
    valid = np.ones(n, dtype=bool)
    valid[n * 4 // 7:n * 4 // 7 + 10] = False
    return y, valid


@pytest.mark.parametrize("hop, alpha", [(256, None), (256, 0), (8, None), (1, 0)])
def test_one_sample_pushes_equal_block_pushes(hop, alpha):
    y, valid = _record(7000)
    w = 1024
    block = StreamingDadev(1.0, w, hop_s=hop, alpha=alpha).push(y, valid)
    eng = StreamingDadev(1.0, w, hop_s=hop, alpha=alpha)
    rows = []
    for i in range(len(y)):
        r = eng.push(y[i:i + 1], valid[i:i + 1])
        rows.append(r)
        assert eng.n_pushed == i + 1
    one = {f: np.concatenate([getattr(r, f) for r in rows]) for f in ("end_index", "adev_dph", "lo_dph", "hi_dph",
                                                                       "edf", "n_terms")}
    assert np.array_equal(one["end_index"], block.end_index)
    assert np.array_equal(one["n_terms"], block.n_terms)
    for f in ("adev_dph", "lo_dph", "hi_dph", "edf"):
        np.testing.assert_allclose(one[f], getattr(block, f), rtol=1e-12)
    # the windows come out in the call that completes them: one row per hop-boundary sample
    assert [len(r) for r in rows].count(1) == len(block)


def test_staged_samples_enter_current_and_larger_pushes():
    y, valid = _record(3000, seed=1)
    w = 1024
    a, b = StreamingDadev(1.0, w, hop_s=512, alpha=0), StreamingDadev(1.0, w, hop_s=512, alpha=0)
    a.push(y[:1200])
    b.push(y[:1100])  # the first window (ending at sample 1023) is out
    for i in range(1100, 1200):
        assert len(b.push(y[i:i + 1])) == 0  # staged: the next window ends at sample 1535
    assert b._staged == 100 <= STAGE and b.n_pushed == a.n_pushed
    np.testing.assert_allclose(b.current().adev_dph, a.current().adev_dph, rtol=1e-12)
    a.push(y[1200:1250])
    for i in range(1200, 1250):
        b.push(y[i:i + 1])
    blk = Block.make(np.arange(1250, 3000) / 1.0, y[1250:], valid=valid[1250:])
    ra, rb = a.push(blk), b.push(blk)
    assert len(ra) == len(rb) == 3
    np.testing.assert_allclose(rb.adev_dph, ra.adev_dph, rtol=1e-12)


def test_frame_statistics_equal_their_definitions():
    rng = np.random.default_rng(3)
    m = np.array([1, 2, 4, 8, 16, 32])
    n = 200
    full = n - 2 * m + 1
    counts = np.tile(full, (7, 1))
    counts[2, 3] -= 40  # gapped entries
    counts[4, 5] = 0  # no terms
    sums = rng.uniform(1.0, 2.0, counts.shape) * counts
    alpha = np.array([[0, 0, 0, -1, -1, -2]] * 3 + [[2, 0, 0, 0, -2, -2]] * 4)
    adev, lo, hi, edf = statistics(sums, counts, m, n, alpha, 0.9)
    with np.errstate(invalid="ignore", divide="ignore"):
        want = np.sqrt(sums / (2.0 * counts))
    e = np.array([edf_effective(edf_full(a, m, n), m, n, c) for a, c in zip(alpha, counts, strict=True)])
    np.testing.assert_allclose(adev, want, rtol=1e-15)
    np.testing.assert_allclose(edf, e, rtol=1e-12)
    ok = counts > 0
    np.testing.assert_allclose(lo[ok], (want * np.sqrt(e / chi2.ppf(0.95, e)))[ok], rtol=1e-12)
    np.testing.assert_allclose(hi[ok], (want * np.sqrt(e / chi2.ppf(0.05, e)))[ok], rtol=1e-12)
    assert np.all(np.isnan(adev[~ok]) & np.isnan(edf[~ok]))
    # a fixed alpha row is the same as that row repeated per window
    one = statistics(sums, counts, m, n, alpha[0], 0.9)
    rep = statistics(sums, counts, m, n, np.tile(alpha[0], (7, 1)), 0.9)
    for u, v in zip(one, rep, strict=True):
        np.testing.assert_array_equal(u, v)


@pytest.mark.parametrize("gap", [False, True])
def test_dadev_intervals_formed_when_read_equal_their_definition(gap):
    """DadevResult forms lo/hi when first read (and window(i) only row i's): they are the
    chi-square interval of each entry's own EDF, one EDF row broadcast or not."""
    y = 1000.0 + np.random.default_rng(5).normal(size=6000)
    valid = np.ones(len(y), bool)
    valid[2500:2510] = not gap
    res = StreamingDadev(1.0, 1024, taus=8, hop_s=1, alpha=0).push(y, valid)
    assert (res.edf.strides[0] == 0) is not gap  # gap-free: one EDF row broadcast over the windows
    lo, hi = chi2_bounds(res.adev_dph, np.array(res.edf), 0.683)
    np.testing.assert_array_equal(res.lo_dph, lo)
    np.testing.assert_array_equal(res.hi_dph, hi)
    for i in (0, 1700, len(res) - 1):
        w = res.window(i)
        np.testing.assert_array_equal(w.lo_dph, lo[i])
        np.testing.assert_array_equal(w.hi_dph, hi[i])


def _brute(seg, sv, m):
    """(ADEV, valid-term count) of one window by direct term sums (a term spanning an
    invalid sample is dropped, one spanning an infinite sample is +inf)."""
    huge = sv & np.isinf(seg)
    c = np.concatenate([[0.0], np.cumsum(np.where(sv & ~huge, seg - 1000.0, 0.0))])
    bad = np.concatenate([[0], np.cumsum(~sv)])
    nh = np.concatenate([[0], np.cumsum(huge)])
    j = np.arange(len(seg) - 2 * m + 1)
    keep = bad[j + 2 * m] == bad[j]
    if (nh[j + 2 * m] != nh[j])[keep].any():
        return np.inf, keep.sum()
    t = ((c[j + 2 * m] - c[j + m]) - (c[j + m] - c[j]))[keep] / m
    return (np.sqrt(np.mean(t * t) / 2.0) if keep.any() else np.nan), keep.sum()


@pytest.mark.parametrize("hop", [1, 3, 64, 700])
def test_tiled_batch_window_sums_equal_brute_force(hop):
    y, valid = _record(4000, seed=2)
    y[2500] = np.inf  # huge: windows holding it are +inf where a term spans it
    w = 2600 if hop == 700 else 1500
    taus = [1.0, 2.0, 3.0, 17.0, 64.0, 200.0, 375.0]
    d = dadev(y, 1.0, w, hop, taus=taus, valid=valid, alpha=0)
    ok = valid & ~np.isnan(y)
    for row in range(0, len(d), max(1, len(d) // 9)):
        end = d.end_index[row]
        seg, sv = y[end - w + 1:end + 1], ok[end - w + 1:end + 1]
        for k, m in enumerate(d.m):
            want, n = _brute(seg, sv, m)
            assert d.n_terms[row, k] == n
            assert d.adev_dph[row, k] == pytest.approx(want, rel=1e-9, nan_ok=True)


def test_oadev_tiles_equal_a_compensated_sum():
    y, valid = _record(50000, seed=4)
    res = oadev(y, 1.0, taus=[1.0, 7.0, 100.0, 3000.0], valid=valid, alpha=0)
    ok = valid & ~np.isnan(y)
    for k, m in enumerate(res.m):
        c = np.concatenate([[0.0], np.cumsum(np.where(ok, y - 1000.0, 0.0))])
        bad = np.concatenate([[0], np.cumsum(~ok)])
        j = np.arange(len(y) - 2 * m + 1)
        keep = bad[j + 2 * m] == bad[j]
        t = ((c[j + 2 * m] - c[j + m]) - (c[j + m] - c[j]))[keep] / m
        assert res.n_terms[k] == keep.sum()
        assert res.adev_dph[k] == pytest.approx(np.sqrt(np.sum(np.sort(t * t)) / (2 * keep.sum())), rel=1e-9)


def test_held_noise_mixture_is_refitted_when_the_curve_changes():
    rng = np.random.default_rng(5)
    w, hop = 4096, 512
    white = rng.normal(size=6 * w)
    walk = np.cumsum(rng.normal(size=6 * w)) * 0.3  # random walk dominates the long taus
    y = np.concatenate([white, white[:3 * w] + walk[:3 * w]])
    d = dadev(y, 1.0, w, hop, alpha=0)
    edf, _ = edf_rows(d.n_terms * 2.0 * d.adev_dph**2, d.n_terms, d.end_index, d.m, w, w // 4)
    first, last = 0, len(d) - 1
    c = d.n_terms * 2.0 * d.adev_dph**2
    np.testing.assert_array_equal(edf[first], row_edf(c[first], d.n_terms[first], d.m, w)[0])
    # held between refits: the last row is that of the last refit, on a window that holds the walk
    refit = np.flatnonzero(np.any(edf[1:] != edf[:-1], axis=1)) + 1
    assert len(refit) and d.end_index[refit[-1]] >= 6 * w
    np.testing.assert_array_equal(edf[last], row_edf(c[refit[-1]], d.n_terms[refit[-1]], d.m, w)[0])
    # the random walk's few EDF at the longest tau (white rate noise alone has about 1.5x more)
    assert edf[last, -1] < 0.8 * edf[first, -1]


def test_model_holds_is_the_z_test_at_every_tau_with_terms():
    rng = np.random.default_rng(9)
    m = np.array([1, 2, 4, 8, 16, 32], dtype=np.int64)
    n = np.array([4000, 4000, 3990, 3000, 0, 10], dtype=np.int64)
    model = np.full(6, 1.0)
    for _ in range(200):
        z_true = rng.normal(scale=2.0, size=6)
        sums = 2.0 * n * np.exp(z_true * np.sqrt(2.0 * m / np.maximum(n, 1) + 0.01))
        sums[rng.random(6) < 0.1] = 0.0  # avar 0: ln = -inf, never holds where there are terms
        use = n > 0
        with np.errstate(divide="ignore"):
            z = np.log(sums[use] / (2.0 * n[use]) / model[use]) / np.sqrt(2.0 * m[use] / n[use] + 0.01)
        assert window_stats.model_holds(model, sums, n, m, HOLD_Z) == bool(np.all(np.abs(z) <= HOLD_Z))


_RUN = ("import numpy as np; from fogmon import jit; from fogmon.davar import kernels; "
        "jit.warm_up_on_first_use = False; "  # one kernel (the warm-up of all: tests/test_jit.py)
        "jit.use_ahead_of_time = False; "  # numba's path, as on a machine where the module was not built
        "print(kernels.reference_level(np.array([3.0, 1.0, 2.0]), np.ones(3, dtype=bool)))")


def _run_with_cache(path):
    p = subprocess.run([sys.executable, "-c", _RUN], capture_output=True, text=True,
                       env={**os.environ, "NUMBA_CACHE_DIR": str(path)})
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["2.0"]
    return p.stderr


def test_an_unusable_or_corrupt_numba_cache_does_not_break_a_run(tmp_path):
    ro = tmp_path / "read_only"
    ro.mkdir()
    ro.chmod(0o555)  # read-only (root may still write: the next case holds for root too)
    try:
        _run_with_cache(ro)
    finally:
        ro.chmod(0o755)
    (tmp_path / "file").write_text("")
    _run_with_cache(tmp_path / "file" / "cache")  # cannot even be created
    good = tmp_path / "cache"
    _run_with_cache(good)
    files = [f for f in good.rglob("*") if f.is_file()]
    assert files
    for f in files:
        f.write_text("garbage")  # a corrupt cache: compiled in memory, one warning
    err = _run_with_cache(good)
    assert err.count("FogmonWarning: numba cache unusable") == 1
