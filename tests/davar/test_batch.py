"""Batch oadev/dadev: brute-force references, gaps, tau grids, input errors."""
import allantools
import numpy as np
import pytest

from fogmon.davar.batch import dadev, oadev
from fogmon.davar.taus import tau_grid
from fogmon.errors import FogmonError

FS = 10.0


def mixed_noise(n, seed=0, bias=1000.0):
    """White + random-walk + white-angle rate noise (deg/h) on a large bias."""
    rng = np.random.default_rng(seed)
    theta = rng.normal(size=n + 1) * 0.5
    return bias + rng.normal(size=n) * 0.3 + np.cumsum(rng.normal(size=n)) * 0.002 + np.diff(theta) * FS


def reference_avar(y, valid, m):
    """Overlapping Allan variance keeping only terms whose 2m samples are all valid, and
    their count: explicit means, no prefix sums."""
    yy = np.where(valid, y, 0.0)
    means = np.convolve(yy, np.ones(m) / m, mode="valid")  # mean of y[j:j+m]
    ok = np.convolve((~valid).astype(float), np.ones(2 * m), mode="valid") == 0
    terms = (means[m:] - means[:-m])[ok]
    return (np.sum(terms**2) / (2 * len(terms)) if len(terms) else np.nan), len(terms)


def test_tau_grids():
    assert tau_grid(10.0, 100).tolist() == [1, 2, 4, 8, 16]
    assert tau_grid(1.0, 100000, "decade").tolist() == [1, 2, 4, 10, 20, 40, 100, 200, 400, 1000, 2000, 4000,
                                                       10000, 20000]
    assert tau_grid(1.0, 40, "all").tolist() == list(range(1, 11))
    assert tau_grid(1.0, 4000, 4).tolist() == [1, 2, 3, 6, 10, 18, 32, 56, 100, 178, 316, 562, 1000]
    assert tau_grid(100.0, 4000, [0.01, 0.5, 0.504, 3.0, 20.0]).tolist() == [1, 50, 300]
    with pytest.raises(FogmonError):
        tau_grid(10.0, 3)
    with pytest.raises(FogmonError):
        tau_grid(10.0, 100, "weekly")
    with pytest.raises(FogmonError):
        tau_grid(0.0, 100)


def test_oadev_matches_allantools_all_taus():
    y = mixed_noise(5000)
    res = oadev(y, FS, taus="all")
    tau, dev, _, n = allantools.oadev(y, rate=FS, data_type="freq", taus=res.tau_s)
    assert len(res.m) == 1250 and np.array_equal(n, res.n_terms)
    assert np.max(np.abs(res.adev_dph / dev - 1)) <= 1e-9


def test_dadev_equals_allantools_on_every_window():
    y = mixed_noise(20000, seed=1)
    d = dadev(y, FS, window_s=300.0, hop_s=37.3, taus=6, t0_s=5.0)
    w = 3000
    assert d.adev_dph.shape == (len(range(0, 20000 - w + 1, 373)), len(d.m))
    assert np.allclose(d.t_s, 5.0 + (np.arange(len(d)) * 373 + (w - 1) / 2) / FS)
    for i, end in enumerate(d.end_index):
        tau, dev, _, n = allantools.oadev(y[end - w + 1:end + 1], rate=FS, data_type="freq", taus=d.tau_s)
        assert np.array_equal(n, d.n_terms[i])
        assert np.max(np.abs(d.adev_dph[i] / dev - 1)) <= 1e-9
    assert d.window(3).adev_dph is not None and np.array_equal(d.window(3).adev_dph, d.adev_dph[3])


def test_gaps_drop_exactly_the_spanning_terms():
    rng = np.random.default_rng(2)
    y = mixed_noise(6000, seed=2)
    valid = rng.random(6000) > 0.002
    valid[3000:3040] = False
    y[~valid] = np.nan  # placeholders as sources deliver them
    res = oadev(y, FS, taus="all")
    for k in (1, 2, 7, 33, 100, 300, 512, 1500):
        ref, count = reference_avar(np.nan_to_num(y), valid, k)
        i = np.flatnonzero(res.m == k)[0]
        assert res.n_terms[i] == count
        if count:
            assert abs(res.adev_dph[i] ** 2 / ref - 1) <= 1e-9
        else:  # every term spans a gap
            assert k >= 512 and np.isnan(res.adev_dph[i])
    # an explicit mask works the same as NaN placeholders
    y2 = np.where(valid, y, 1e9)
    assert np.array_equal(oadev(y2, FS, valid=valid).adev_dph, oadev(y, FS).adev_dph, equal_nan=True)


def test_dadev_gap_windows():
    y = mixed_noise(4000, seed=3)
    valid = np.ones(4000, bool)
    valid[1500:1510] = False
    d = dadev(y, FS, 100.0, 25.0, valid=valid)
    for i, end in enumerate(d.end_index):
        sl = slice(end - 999, end + 1)
        for k, m in enumerate(d.m):
            ref, count = reference_avar(y[sl], valid[sl], m)
            assert d.n_terms[i, k] == count
            assert abs(d.adev_dph[i, k] ** 2 / ref - 1) <= 1e-9
    # EDF shrinks with the fraction of terms lost
    hit = d.n_terms[:, 0] < 999
    assert hit.any() and np.all(d.edf[hit, 0] < d.edf[~hit, 0].min())


def test_large_bias_costs_no_precision():
    y = mixed_noise(20000, seed=4, bias=0.0)
    a = oadev(y, FS).adev_dph
    b = oadev(y + 3.6e6, FS).adev_dph  # 1000 deg/s bias in deg/h
    assert np.max(np.abs(b / a - 1)) <= 1e-9


def test_bad_input_is_a_one_line_error():
    with pytest.raises(FogmonError, match="valid mask shape"):
        oadev(np.zeros(100), FS, valid=np.ones(99, bool))
    with pytest.raises(FogmonError, match="one-dimensional"):
        oadev(np.zeros((10, 10)), FS)
    with pytest.raises(FogmonError, match="window_s"):
        dadev(np.zeros(100), FS, window_s=0.0)


def test_all_invalid_window_is_nan_with_zero_terms():
    y = np.full(400, np.nan)
    res = oadev(y, FS)
    assert np.all(res.n_terms == 0) and np.all(np.isnan(res.adev_dph)) and np.all(np.isnan(res.lo_dph))
