"""Issue 28.1: under a model with a rate random walk (K), the mean-type candidates' bars
come from the model's own simulations (explain.scan_null), so a chance step or ramp of
the walk is not named; without K nothing is simulated. The spectral tests read a walk
without its line, and a change-point scan pays for the positions it searches."""
import numpy as np
import pytest
from scipy.stats import chi2

from fogmon.davar.theory import markov_adev
from fogmon.explain import mismatch
from fogmon.explain.analysis import whittle_context
from fogmon.explain.bootstrap import bootstrap
from fogmon.explain.candidates import CANDIDATES
from fogmon.explain.candidates.base import bridged, periodogram
from fogmon.explain.candidates.mean import chance_step_gain
from fogmon.explain.explainer import deterministic_dph, explain, stochastic_part
from fogmon.explain.options import Options
from fogmon.explain.replicas import Replicas
from fogmon.explain.scan_null import allan_slope, calibrated_kinds
from fogmon.explain.selection import candidates
from fogmon.sim.model import EFFECT_KINDS, Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate

FS = 10.0
N = 4096
WALK = SensorModel(FS, 0.0, Noise(N_dpsh=0.02, B_dph=0.1, K_dphsh=2.0))


def test_a_model_with_k_or_dominant_flicker_calibrates_the_mean_type_kinds():
    flicker = SensorModel(FS, 0.0, Noise(N_dpsh=0.02, B_dph=0.1))   # B's floor meets N's ADEV at about 330 s
    assert calibrated_kinds(flicker, 40.0) == ()                    # white noise dominates at 10 s
    assert calibrated_kinds(flicker, 4000.0) == calibrated_kinds(WALK, 40.0)   # flicker dominates at 1000 s
    kinds = calibrated_kinds(WALK, 40.0)
    assert "bias_step" in kinds and "rate_ramp" in kinds
    assert all(EFFECT_KINDS[k].nature == "mean" for k in kinds)


def test_the_walk_raises_the_bars_of_steps_and_ramps_above_bic():
    t = np.arange(N) / FS
    valid = np.ones(N, bool)
    null = bootstrap(Replicas(WALK, t, {}, valid), mismatch.make_grid(N, FS), 20, 3, 0.01, 1)
    rec = simulate(WALK, duration_s=N / FS, seed=5)
    y = rec.rate_dph - rec.rate_dph.mean()
    ctx = whittle_context(stochastic_part(WALK), {}, t, valid, y)
    by_kind = {c.kind: c for c in candidates(ctx, {}, null.scan_bars)}
    for kind in ("bias_step", "rate_ramp"):
        c = by_kind[kind]   # the null's bar is an excess over the kind's own search bar (0 for a ramp)
        assert c.chance_bar == c.search_bar + null.scan_bars[kind]
        assert c.chance_bar > c.k * ctx.penalty and c.bar(ctx.penalty) == c.chance_bar


def test_a_null_walk_names_nothing():
    # without the simulated bars this record names a bias step (BIC's bar alone)
    rec = simulate(WALK, duration_s=N / FS, seed=0)
    res = explain(rec, WALK, Options(n_boot=20, workers=1))
    assert res.accepted == []


def test_a_null_flicker_record_names_no_ramp_or_step():
    """N, B, R at 2 Hz over 6 h: flicker holds ~98 % of the Allan variance at T / 4, and its
    chance excursions beat BIC's bar as a ramp or a step (2 of 25 such records named one,
    found by an outside check); with the simulated bars, nothing."""
    model = SensorModel(2.0, 0.1, Noise(N_dpsh=0.01, B_dph=0.1, R_dphh=2.0))
    rec = simulate(model, duration_s=6 * 3600.0, seed=3005)   # names a rate ramp with BIC's bar alone
    res = explain(rec, model, Options(workers=1))
    assert [a.cand.kind for a in res.accepted] == []


MARKOV_LONG = SensorModel(10.0, 0.0, Noise(N_dpsh=0.01, B_dph=0.005),
                          [Effect("markov", {"tau_c_s": 5000.0, "sigma_dph": 0.5})])


def test_a_markov_term_long_beside_the_record_calibrates_the_mean_type_kinds():
    """A Gauss-Markov term walks within a record shorter than its correlation time: the
    slope of the model's Allan variance at T / 4 (allan_slope, theory's markov_adev for
    the term alone) decides, not the term's kind."""
    short = SensorModel(10.0, 0.0, Noise(N_dpsh=0.01), [Effect("markov", {"tau_c_s": 10.0, "sigma_dph": 0.3})])
    for model, tau_c in ((short, 10.0), (MARKOV_LONG, 5000.0)):
        alone = SensorModel(10.0, 0.0, Noise(), model.effects)
        tau = 900.0 * np.array([2 ** -0.25, 2 ** 0.25])
        theory = np.log(markov_adev(tau, model.effects[0].params["sigma_dph"], tau_c)) * 2
        assert abs(allan_slope(alone, 900.0, 36001) - (theory[1] - theory[0]) / np.log(2 ** 0.5)) < 1e-3
    assert allan_slope(SensorModel(10.0, 0.0, Noise(N_dpsh=0.01)), 900.0, 36001) == pytest.approx(-1.0, abs=1e-3)
    assert calibrated_kinds(short, 3600.0) == ()
    assert calibrated_kinds(MARKOV_LONG, 3600.0) == calibrated_kinds(WALK, 40.0)


def test_a_null_record_of_a_long_markov_term_names_no_ramp():
    """N, B and a Gauss-Markov term of tau_c 5000 s over 1 h at 10 Hz: an outside check
    named a chance ramp, step or settling on 9 of 16 records (the bars not simulated:
    no K, no flicker), 1 periodic and 1 glitch in 20 with them."""
    rec = simulate(MARKOV_LONG, duration_s=3600.0, seed=701)   # names a rate ramp with BIC's bar alone
    res = explain(rec, MARKOV_LONG, Options(workers=1))
    assert [a.cand.kind for a in res.accepted] == []


def _context(model: SensorModel, seed: int):
    rec = simulate(model, duration_s=2 ** 16 / model.sample_rate_hz if model.noise.K_dphsh else 2 ** 15, seed=seed)
    t = np.asarray(rec.t_s, float)
    y = rec.rate_dph - deterministic_dph(model, t, {}, float(model.sample_rate_hz))
    return whittle_context(stochastic_part(model), {}, t, np.ones(len(t), bool), y - y.mean())


def test_spectral_tests_read_a_walk_without_its_line():
    ctx = whittle_context(stochastic_part(WALK), {}, np.arange(N) / FS, np.ones(N, bool),
                          np.random.default_rng(1).standard_normal(N))
    line = 0.3 * (np.arange(N) - N / 2) / N
    assert np.allclose(bridged(ctx.y + line, ctx.valid), bridged(ctx.y, ctx.valid))
    assert np.allclose(periodogram(ctx).I[:5], np.abs(np.fft.rfft(bridged(ctx.y, ctx.valid))[1:6]) ** 2 / N)
    white = whittle_context(SensorModel(FS, 0.0, Noise(N_dpsh=0.02)), {}, ctx.t_s, ctx.valid, ctx.y)
    assert np.allclose(periodogram(white).I[:5], np.abs(white.Yf[1:6]) ** 2 / N)  # no walk: the residual as it is


def test_a_walks_excursion_does_not_pose_as_a_wrong_b():
    # calibration.py's null record 2 (N 0.02, B 0.1, K 0.4 at 10 Hz, 1.8 h): the walk's wrap
    # jump raised the lowest bins together and a B of 0.164 won a deviance of 36 over BIC's 11
    ctx = _context(SensorModel(10.0, noise=Noise(0.0, 0.02, 0.1, 0.4)), 1_000_003 + 2)
    c = CANDIDATES["noise"](ctx)
    assert c is None or c.gain < c.bar(ctx.penalty)


def test_a_step_search_pays_for_its_positions():
    # calibration.py's null record 28 (N 0.05, B 0.2, R 1 at 1 Hz, 9 h): a chance step of the
    # flicker beat BIC's 2 ln n (21.1 > 20.8), not the scan's chance bar
    u = chance_step_gain(32113, 1e-3)
    assert np.isclose(32113 * chi2.sf(u, 1), 1e-3) and u > 2 * np.log(2 ** 15)
    ctx = _context(SensorModel(1.0, noise=Noise(0.0, 0.05, 0.2, 0.0, 1.0)), 1_000_003 + 28)
    c = CANDIDATES["bias_step"](ctx)
    assert c.gain > c.k * ctx.penalty and c.gain < c.bar(ctx.penalty)
