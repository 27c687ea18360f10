"""The mean-type fits' standard errors under long memory (docs/explain.md, "Standard
errors under long memory"): the Whittle GLS estimator as weights in time, the exact
covariance of such functionals under the model's law, and judged_gls's errors against
the scatter of its estimates over draws of that law."""
from __future__ import annotations

import numpy as np
import pytest

from fogmon.explain.analysis import whittle_context
from fogmon.explain.candidates.base import EXACT_LAW, LONG_MEMORY, judged_gls
from fogmon.explain.replicas import Replicas
from fogmon.sim.model import Noise, SensorModel

FS_HZ = 10.0
N = 4096
T_S = np.arange(N) / FS_HZ
#: white noise beside a strong rate random walk and flicker (deg/sqrt(h), deg/h, deg/h/sqrt(h))
WALK = SensorModel(FS_HZ, noise=Noise(N_dpsh=0.01, B_dph=0.05, K_dphsh=2.0))


def _gaps() -> np.ndarray:
    valid = np.ones(N, bool)
    valid[1000:1300] = False
    valid[3000:3050] = False
    return valid


def _residual(law: Replicas, seed: int) -> np.ndarray:
    r = law.draw(seed)
    v = law.valid
    return np.where(v, r - np.nanmean(r[v]), 0.0)


@pytest.mark.parametrize("gaps", [False, True])
def test_weights_reproduce_the_estimate(gaps):
    valid = _gaps() if gaps else np.ones(N, bool)
    law = Replicas(WALK, T_S, {}, valid)
    ctx = whittle_context(WALK, {}, T_S, valid, _residual(law, 3))
    X = np.column_stack(((T_S >= 150.0).astype(float), np.sin(2 * np.pi * T_S / 37.0)))
    Xf = ctx.wh.fft(X)
    fit = ctx.wh.gls(Xf, ctx.Yf)
    a = ctx.wh.weights(Xf, fit.cov)
    assert a @ ctx.y == pytest.approx(fit.beta, rel=1e-9, abs=1e-12)
    assert np.all(a[:, ~valid] == 0.0)
    assert np.abs(a[:, valid].sum(axis=1)).max() < 1e-9      # the mean is profiled out


def test_functional_cov_is_the_draws_covariance():
    law = Replicas(WALK, T_S, {}, np.ones(N, bool))
    rng = np.random.default_rng(1)
    a = rng.standard_normal((2, N)) * np.linspace(0.0, 1.0, N)
    a -= a.mean(axis=1, keepdims=True)
    V = law.functional_cov(a)
    draws = np.array([a @ law.draw(100 + i) for i in range(600)])
    emp = np.cov(draws.T)
    # 600 draws: a variance's relative standard error is sqrt(2 / 599) = 5.8 %
    assert np.diag(emp) == pytest.approx(np.diag(V), rel=0.2)
    assert emp[0, 1] / np.sqrt(emp[0, 0] * emp[1, 1]) == pytest.approx(V[0, 1] / np.sqrt(V[0, 0] * V[1, 1]), abs=0.12)


@pytest.mark.parametrize("gaps", [False, True])
def test_step_errors_match_the_scatter_under_a_random_walk(gaps):
    """A bias step's Whittle error is ~3x too small beside this random walk; under the law
    it is the estimate's scatter over the law's draws."""
    valid = _gaps() if gaps else np.ones(N, bool)
    law = Replicas(WALK, T_S, {}, valid)
    X = (T_S >= 150.0).astype(float)[:, None]
    est, nominal, exact = [], [], []
    for i in range(150):
        ctx = whittle_context(WALK, {}, T_S, valid, _residual(law, 1000 + i))
        nominal.append(judged_gls(ctx, X).se[0])
        ctx.cache.update({LONG_MEMORY: True, EXACT_LAW: law})
        fit = judged_gls(ctx, X)
        est.append(fit.beta[0])
        exact.append(fit.se[0])
    scatter = float(np.std(est))
    assert np.median(exact) == pytest.approx(scatter, rel=0.2)     # 150 draws: 5.8 % standard error
    assert np.median(nominal) < 0.6 * scatter


def test_periodic_errors_hold_the_frequency_free():
    """A line's phase (stated at t = 0) moves with its frequency's error by the lever from
    the record's middle; its error was the amplitude's over the amplitude (z sd 1.9 on
    white noise), now from the fit with the frequency free."""
    from fogmon.explain.candidates.mean import periodic

    m = SensorModel(FS_HZ, noise=Noise(N_dpsh=0.01))
    law = Replicas(m, T_S, {}, np.ones(N, bool))
    period, amp, phase = 41.3, 0.3, 0.7
    z = []
    for i in range(100):
        y = law.draw(i) + amp * np.sin(2 * np.pi * T_S / period + phase)
        c = periodic(whittle_context(m, {}, T_S, np.ones(N, bool), y - y.mean()))
        z.append([(c.params["period_s"] - period) / c.se["period_s"],
                  (c.params["amplitude_dph"] - amp) / c.se["amplitude_dph"],
                  np.remainder(c.params["phase_rad"] - phase + np.pi, 2 * np.pi) / c.se["phase_rad"]
                  - np.pi / c.se["phase_rad"]])
    sd = np.std(np.array(z), axis=0)
    assert np.all((sd > 0.75) & (sd < 1.3)), sd      # 100 records: sd's standard error 7 %
