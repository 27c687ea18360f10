"""Live outlier rejection: finds spikes, leaves noise and motion alone, does not depend
on how the stream is cut into blocks, and rejects Gaussian noise at the stated rate."""
from __future__ import annotations

import numpy as np
import pytest

from fogmon.methods.live_outliers import OutlierRejector, false_rejection


def _run(rej: OutlierRejector, y, valid, sizes) -> np.ndarray:
    out, i, k = [], 0, 0
    while i < len(y):
        s = slice(i, i + sizes[k % len(sizes)])
        out.append(rej.push(y[s], valid[s]))
        i, k = s.stop, k + 1
    return np.concatenate(out)


@pytest.fixture(scope="module")
def spiky():
    rng = np.random.default_rng(0)
    n = 400_000
    y = rng.normal(0.0, 10.0, n)
    valid = np.ones(n, bool)
    valid[rng.choice(n, 500, replace=False)] = False
    spikes = rng.choice(np.flatnonzero(valid[:]), 300, replace=False)
    spikes = spikes[spikes > 10_000]  # after the noise estimate has settled
    y[spikes] += rng.choice([-1.0, 1.0], len(spikes)) * rng.uniform(100.0, 1000.0, len(spikes))
    y[~valid] = np.nan
    return y, valid, np.sort(spikes)


def test_every_spike_and_nothing_else(spiky):
    y, valid, spikes = spiky
    rej = OutlierRejector()
    mask = _run(rej, y, valid, [1000])
    assert np.array_equal(np.flatnonzero(mask), spikes)
    assert rej.rejected == len(spikes)
    assert not mask[~valid].any()


def test_block_boundaries_do_not_matter(spiky):
    y, valid, _ = spiky
    a = _run(OutlierRejector(), y, valid, [1000])
    b = _run(OutlierRejector(), y, valid, [1, 7, 4096, 255, 33_000])
    assert np.array_equal(a, b)


def test_gaussian_noise_is_rejected_at_the_stated_rate():
    n = 1_000_000
    y = np.random.default_rng(1).normal(0.0, 3.0, n)
    mask = _run(OutlierRejector(4.0), y, np.ones(n, bool), [8192])
    expected = false_rejection(4.0) * n  # about 400
    assert abs(mask.sum() - expected) < 5 * np.sqrt(expected)


def test_smooth_motion_and_quantization_are_not_outliers():
    rng = np.random.default_rng(2)
    t = np.arange(400_000) / 1000.0
    y = np.round((rng.normal(0.0, 3.0, len(t)) + 5000.0 * np.sin(2 * np.pi * t / 20.0)) / 5.0) * 5.0
    assert not _run(OutlierRejector(), y, np.ones(len(t), bool), [4096]).any()


def test_bad_threshold_is_refused():
    with pytest.raises(ValueError, match="finite number > 0"):
        OutlierRejector(float("nan"))
