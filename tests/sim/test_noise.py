"""Noise generators: chunking invariance, reproducibility, exact ADEV of the flicker and
AR(1) processes against theory, and a quick statistical version of
validation/sim_noise.py."""
from __future__ import annotations

import importlib.util
import math

import allantools
import numpy as np
import pytest
from helpers import REPO

from fogmon.davar.theory import markov_adev
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.noise import (
    FLICKER_FLOOR,
    Flicker,
    GaussMarkov,
    LowpassNoise,
    RandomWalk,
    WhiteAngle,
    WhiteRate,
    ar1_adev_exact,
    flicker_adev_exact,
    lowpass_adev_exact,
    lowpass_filter,
)
from fogmon.sim.simulate import iter_simulate, simulate

ROOT = REPO


def _validation():
    spec = importlib.util.spec_from_file_location("sim_noise_validation", ROOT / "validation" / "sim_noise.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


GENERATORS = {
    "Q": lambda rng: WhiteAngle(0.3, 100.0, rng),
    "N": lambda rng: WhiteRate(100.0, rng),
    "B": lambda rng: Flicker(0.1, 100.0, rng, tau_hi_s=1e4),
    "K": lambda rng: RandomWalk(1.0, 100.0, rng),
    "GM": lambda rng: GaussMarkov(1.0, 3.0, 100.0, rng),
    "LP": lambda rng: LowpassNoise(1.0, 7.0, 3, 100.0, rng),
}


@pytest.mark.parametrize("name", sorted(GENERATORS))
def test_any_chunking_gives_identical_bits(name):
    whole = GENERATORS[name](np.random.default_rng(7)).generate(10000)
    g = GENERATORS[name](np.random.default_rng(7))
    parts = [g.generate(k) for k in (1, 0, 999, 4000, 5000)]
    assert np.array_equal(whole, np.concatenate(parts))


def test_simulate_equals_streamed_blocks_for_every_term():
    m = SensorModel(100.0, 0.3, Noise(0.1, 0.05, 0.02, 0.01, 0.5),
                    [Effect("markov", {"tau_c_s": 5.0, "sigma_dph": 0.1}),
                     Effect("bandwidth", {"cutoff_hz": 20.0, "order": 3, "taps": []})])
    rec = simulate(m, duration_s=300.0, seed=11)
    streamed = np.concatenate([b.rate_dph for b in iter_simulate(m, 300.0, seed=11, chunk_samples=777)])
    assert np.array_equal(rec.rate_dph, streamed)
    assert rec.meta["seed"] == "11" and rec.meta["sample_rate_hz"] == "100"


def test_seed_reproducible_and_terms_have_independent_streams():
    base = SensorModel(100.0, 0.0, Noise(N_dpsh=0.05))
    a = simulate(base, duration_s=10.0, seed=5).rate_dph
    assert np.array_equal(a, simulate(base, duration_s=10.0, seed=5).rate_dph)
    assert not np.array_equal(a, simulate(base, duration_s=10.0, seed=6).rate_dph)
    # adding an effect leaves the white-noise realization unchanged
    plus = SensorModel(100.0, 0.0, Noise(N_dpsh=0.05), [Effect("bias_step", {"t_s": 5.0, "step_dph": 1.0})])
    b = simulate(plus, duration_s=10.0, seed=5).rate_dph
    assert np.array_equal(a[:500], b[:500]) and np.allclose(a[500:] + 1.0, b[500:], rtol=0, atol=1e-12)


def test_seed_none_reports_its_entropy():
    rec = simulate(SensorModel(10.0, 0.0, Noise(N_dpsh=1.0)), duration_s=5.0)
    again = simulate(SensorModel(10.0, 0.0, Noise(N_dpsh=1.0)), duration_s=5.0, seed=int(rec.meta["seed"]))
    assert np.array_equal(rec.rate_dph, again.rate_dph)


def test_flicker_generator_exact_floor_within_1pct_over_band():
    sample_rate_hz, dur = 100.0, 3600.0 * 24
    m = np.unique(np.round(np.logspace(np.log10(20), np.log10(dur * sample_rate_hz / 10), 80)).astype(int))
    r = flicker_adev_exact(m, 0.05, sample_rate_hz, 10 * dur) / (FLICKER_FLOOR * 0.05)
    assert np.all(np.abs(r - 1) < 0.011), (r.min(), r.max())
    # the first few tau0 sit above the floor, as discrete flicker does (Kasdin: 0.798 B at m = 1)
    assert 1.15 < flicker_adev_exact(np.array([1]), 1.0, sample_rate_hz, 10 * dur)[0] / FLICKER_FLOOR < 1.35


def test_ar1_exact_matches_continuous_markov_for_long_correlation_time():
    sample_rate_hz, tc = 100.0, 20.0
    tau = np.array([1.0, 10.0, 37.8, 100.0, 1000.0])
    assert np.allclose(
        ar1_adev_exact(tau * sample_rate_hz, 0.3, tc, sample_rate_hz), markov_adev(tau, 0.3, tc), rtol=5e-3
    )
    # peak 0.618 sigma at 1.89 tau_c (docs/sim.md)
    m = np.arange(1, 20000)
    a = ar1_adev_exact(m, 1.0, tc, sample_rate_hz)
    assert abs(a.max() - 0.618) < 0.005 and abs(m[np.argmax(a)] / sample_rate_hz / tc - 1.89) < 0.03


def test_white_angle_adev_exact_against_allantools():
    """Q: sqrt(3) Q / tau at every tau, measured with an independent ADEV (allantools)."""
    q, sample_rate_hz = 0.5, 200.0
    x = WhiteAngle(q, sample_rate_hz, np.random.default_rng(3)).generate(400000)
    taus, ad, _, _ = allantools.oadev(
        x, rate=sample_rate_hz, data_type="freq", taus=np.array([1, 4, 16, 64]) / sample_rate_hz
    )
    assert np.allclose(ad, math.sqrt(3) * q / taus, rtol=0.02)


def test_quick_validation_all_terms_within_tolerance():
    """validation/sim_noise.py on 40 seeds x 4096 samples: within the validation's
    tolerance or 3.5 standard errors of the 40-seed mean, whichever is larger."""
    val = _validation()
    sample_rate_hz, n = 100.0, 4096
    for name, build, theory, tau_min, tol, alpha in val.cases(sample_rate_hz, n):
        ok, tau, ratio = val.run_case(name, build, theory, tau_min, tol, alpha, sample_rate_hz, n, 40, sigmas=3.5)
        assert ok, (name, tau, ratio)


@pytest.mark.parametrize("cutoff_hz,order", [(31.7, 1), (10.0, 2), (4.0, 4), (45.0, 3)])
def test_lowpass_noise_adev_exact_against_its_psd_integral(cutoff_hz, order):
    """lowpass_noise's exact ADEV (from its autocovariance) against an independent
    reference: AVAR(m) = integral over the circle of S(nu) sin^4(pi m nu) / (m^2 sin^2(pi nu)),
    S = sigma^2 |H|^2 / mean |H|^2, on a grid of 2^21 frequencies."""
    from scipy.signal import sosfreqz

    sample_rate_hz, sigma = 100.0, 2.5
    nu = (np.arange(1 << 21) + 0.5) / (1 << 21) / 2.0  # midpoints over (0, 1/2)
    _, h = sosfreqz(lowpass_filter(cutoff_hz, order, sample_rate_hz), worN=2 * np.pi * nu)
    S = sigma ** 2 * np.abs(h) ** 2 / np.mean(np.abs(h) ** 2)
    m = np.array([1, 2, 3, 5, 16, 100, 1000])
    ref = [2.0 * np.mean(S * np.sin(np.pi * k * nu) ** 4 / (k * k * np.sin(np.pi * nu) ** 2)) for k in m]
    assert lowpass_adev_exact(m, sigma, cutoff_hz, order, sample_rate_hz) ** 2 == pytest.approx(ref, rel=1e-6)


def test_lowpass_noise_generator_is_stationary_from_its_first_sample_with_its_exact_adev():
    sample_rate_hz, sigma, cutoff_hz, order = 250.0, 110.0, 31.7, 2
    first = np.array([LowpassNoise(sigma, cutoff_hz, order, sample_rate_hz, np.random.default_rng(s)).generate(2)
                      for s in range(4000)])
    assert np.std(first[:, 0]) == pytest.approx(sigma, rel=0.05)  # 4000 draws: 1.1 % scatter
    x = LowpassNoise(sigma, cutoff_hz, order, sample_rate_hz, np.random.default_rng(1)).generate(1_000_000)
    m = np.array([1, 2, 4, 16, 64])
    taus, ad, _, _ = allantools.oadev(x, rate=sample_rate_hz, data_type="freq", taus=m / sample_rate_hz)
    assert np.allclose(ad, lowpass_adev_exact(m, sigma, cutoff_hz, order, sample_rate_hz), rtol=0.02)
