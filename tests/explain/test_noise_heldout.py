"""The held-out check of the ``noise`` kind (corrected IEEE-952 coefficients): a half whose
own fit corrects nothing predicts with the whole record's correction, so a correction
that neither half finds on its own is still judged (a wrong coefficient is stationary:
it must lower the deviance of both halves), instead of passing with "chi2 drop 0.0
(expected 0.0)" on both."""
import numpy as np

from fogmon.explain.analysis import whittle_context
from fogmon.explain.candidates.base import WHOLE_RECORD_NOTE
from fogmon.explain.candidates.coefficients import noise
from fogmon.explain.selection import _heldout
from fogmon.sim.model import Noise, SensorModel
from fogmon.sim.simulate import simulate

FS = 10.0
FOG = Noise(N_dpsh=0.02, B_dph=0.02)


def _ctx(y_extra, seed: int, truth: Noise = FOG):
    rec = simulate(SensorModel(FS, 0.0, truth, []), duration_s=7200.0, seed=seed)
    y = rec.rate_dph + y_extra(rec.t_s)
    return whittle_context(SensorModel(FS, 0.0, FOG, []), {}, rec.t_s, np.ones(len(y), bool), y - y.mean())


def test_a_settling_late_in_the_record_is_not_a_wrong_b():
    # a 2 deg/h settling (tau 200 s) starting at 3000 s of 7200 s: the whole record's Allan
    # fit reads it as B about 0.14 deg/h (the model's 0.02 outside the interval), neither
    # half's own fit corrects anything; that B raises the deviance of the half without the
    # settling. Before, both halves were skipped and the check passed.
    def settling(t):
        return np.where(t >= 3000.0, 2.0 * np.exp(-(t - 3000.0) / 200.0), 0.0)

    ctx = _ctx(settling, seed=1)
    c = noise(ctx)
    assert c is not None and "B_dph" in c.params and c.bic_gain(ctx.penalty) > 0
    ok, note = _heldout(ctx, c)
    assert not ok, note
    assert WHOLE_RECORD_NOTE in note


def test_a_stationary_wrong_b_still_passes():
    # the model's B 0.02, the gyro's 0.2: found by each half's own fit and by the whole record's
    ctx = _ctx(lambda t: 0.0 * t, seed=2, truth=Noise(N_dpsh=0.02, B_dph=0.2))
    c = noise(ctx)
    assert c is not None and "B_dph" in c.params
    ok, note = _heldout(ctx, c)
    assert ok, note


def _warm_ups(t):
    # two settlings from the start: 5 deg/h with tau 300 s and 5 deg/h with tau 3000 s
    return 5.0 * np.exp(-t / 300.0) + 5.0 * np.exp(-t / 3000.0)


def test_a_double_warm_up_is_not_a_wrong_k():
    # over 3 h at 10 Hz (N 0.01, B 0.01 in the model and the gyro): the whole record's
    # Allan fit reads the drift as K about 0.5 deg/h/sqrt(h), and it was named "your K is
    # 0.547, not 0"; that correction lowers the first half's deviance some 100x more than
    # the second's
    rec = simulate(SensorModel(FS, 0.0, Noise(N_dpsh=0.01, B_dph=0.01), []), duration_s=3 * 3600.0, seed=1)
    y = rec.rate_dph + _warm_ups(rec.t_s)
    ctx = whittle_context(SensorModel(FS, 0.0, Noise(N_dpsh=0.01, B_dph=0.01), []), {}, rec.t_s,
                          np.ones(len(y), bool), y - y.mean())
    c = noise(ctx)
    assert c is not None and "K_dphsh" in c.params
    ok, note = _heldout(ctx, c)
    assert not ok, note
    assert "not stationary" in note


def test_a_stationary_wrong_k_still_passes():
    ctx = _ctx(lambda t: 0.0 * t, seed=2, truth=Noise(N_dpsh=0.02, B_dph=0.02, K_dphsh=1.0))
    c = noise(ctx)
    assert c is not None and "K_dphsh" in c.params
    ok, note = _heldout(ctx, c)
    assert ok, note
