"""Mismatch map statistics: ln Allan variance cells against allantools, the Gumbel
max-statistic law against scipy, calibration of z under the null, region labelling."""
import math

import allantools
import numpy as np
import pytest
from scipy import stats

from fogmon.explain import mismatch


def test_log_avar_matches_allantools_per_window_and_whole_record():
    rng = np.random.default_rng(0)
    sample_rate_hz = 10.0
    y = rng.standard_normal(4000) + 0.01 * np.cumsum(rng.standard_normal(4000))
    g = mismatch.make_grid(len(y), sample_rate_hz, window_s=100.0)
    cell, whole = mismatch.log_avar(y, np.ones(len(y), bool), g)
    assert cell.shape == (len(g.starts), len(g.m))
    for i in (0, len(g.starts) - 1):
        seg = y[g.starts[i]: g.starts[i] + g.window_n]
        _, ad, _, _ = allantools.oadev(seg, rate=sample_rate_hz, data_type="freq", taus=g.tau_s)
        assert np.allclose(np.exp(cell[i] / 2), ad, rtol=1e-9)
    _, ad, _, _ = allantools.oadev(y, rate=sample_rate_hz, data_type="freq", taus=g.tau_whole_s)
    assert np.allclose(np.exp(whole / 2), ad, rtol=1e-9)


def test_grid_defaults_and_too_short_error():
    g = mismatch.make_grid(80_000, 10.0)
    assert g.window_n == 10_000 and g.hop_n == 2_500 and len(g.starts) == 29
    assert g.m[-1] <= g.window_n // 4 and g.m_whole[-1] <= 80_000 // 4
    with pytest.raises(Exception, match="too short for the 600 s map window"):
        mismatch.make_grid(1000, 1.0, window_s=600.0, name="rec.csv")


def test_gumbel_fit_and_tail_match_scipy():
    x = stats.gumbel_r.rvs(loc=3.0, scale=0.4, size=20000, random_state=1)
    g = mismatch.Gumbel.fit(x)
    assert g.loc == pytest.approx(3.0, abs=0.01) and g.scale == pytest.approx(0.4, abs=0.01)
    assert g.isf(0.01) == pytest.approx(stats.gumbel_r.isf(0.01, g.loc, g.scale), rel=1e-12)
    assert g.sf(4.0) == pytest.approx(stats.gumbel_r.sf(4.0, g.loc, g.scale), rel=1e-12)
    assert g.median == pytest.approx(stats.gumbel_r.median(g.loc, g.scale), rel=1e-12)


def _fake_cells(rng, B, T=30, M=8):
    """ln-chi2 like cells: per-tau spread decreasing with tau, correlated along tau."""
    sd = np.linspace(0.05, 0.6, M)
    e = rng.standard_normal((B, T, M))
    e[..., 1:] = 0.6 * e[..., :-1] + 0.8 * e[..., 1:]
    return 2.0 + sd * e


def test_null_z_is_standard_and_threshold_controls_family_wise_error():
    rng = np.random.default_rng(2)
    B = 60
    null = mismatch.build_null(_fake_cells(rng, B), _fake_cells(rng, B, T=1)[:, 0], alpha=0.05)
    fresh = _fake_cells(rng, 400)
    z = np.stack([mismatch.zscores(c, np.zeros(8), null)[0] for c in fresh])
    assert np.mean(z) == pytest.approx(0.0, abs=0.05)
    assert np.mean(z ** 2) == pytest.approx(1.0, abs=0.1)
    fwer = np.mean(np.max(np.abs(z).reshape(400, -1), axis=1) > null.threshold)
    assert 0.01 <= fwer <= 0.12          # nominal 5 %, 60 replicates


def test_regions_are_labelled_with_span_sign_and_ratio():
    rng = np.random.default_rng(3)
    B = 40
    g = mismatch.make_grid(200_000, 100.0, window_s=200.0)  # 37 windows, hop 50 s
    T, M = len(g.starts), len(g.m)
    cells = 1.0 + 0.1 * rng.standard_normal((B, T, M))
    null = mismatch.build_null(cells, 1.0 + 0.1 * rng.standard_normal((B, len(g.m_whole))))
    rec = 1.0 + 0.1 * rng.standard_normal((T, M))
    rec[5:9, 3:6] += 1.0          # excess: ADEV ratio exp(0.5) = 1.65
    rec[20:22, 0:2] -= 1.0        # deficit
    z, zw = mismatch.zscores(rec, np.full(len(g.m_whole), 1.0), null)
    regs = mismatch.find_regions(z, zw, null, g)
    assert len(regs) == 2
    ex = [r for r in regs if r.sign > 0][0]
    de = [r for r in regs if r.sign < 0][0]
    assert ex.t_start_s == pytest.approx(5 * 50.0) and ex.t_end_s == pytest.approx(8 * 50.0 + 200.0)
    assert ex.tau_min_s == pytest.approx(g.tau_s[3]) and ex.tau_max_s == pytest.approx(g.tau_s[5])
    assert ex.ratio == pytest.approx(math.exp(0.5), rel=0.05) and len(ex.cells) == 12
    assert de.ratio == pytest.approx(math.exp(-0.5), rel=0.05) and de.p_value < 1e-6
    js = ex.as_json()
    for k in ("t_start_s", "t_end_s", "tau_min_s", "tau_max_s", "ratio", "p_value"):
        assert k in js


def test_compare_maps_has_the_null_law_of_the_map():
    rng = np.random.default_rng(4)
    B = 50
    null = mismatch.build_null(_fake_cells(rng, B), _fake_cells(rng, B, T=1)[:, 0])
    a, b = _fake_cells(rng, 2)
    d = mismatch.compare_maps(a, b, null)
    assert np.mean(d ** 2) == pytest.approx(1.0, abs=0.25)
