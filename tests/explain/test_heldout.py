"""The held-out check of a mean-type effect (selection._heldout_mean): a design column
one half does not hold predicts nothing there and is fitted freely in the other half; in a
record cut into pieces it judges the effect against the noise of a centred residual."""
import numpy as np
import pytest

from fogmon.explain.analysis import whittle_context
from fogmon.explain.candidates.mean import bias_step, rate_ramp
from fogmon.explain.selection import _heldout, _heldout_mean, judged_psd
from fogmon.sim.model import Noise, SensorModel


def test_a_branch_absent_from_one_half_does_not_fail_the_check():
    # a thermal drift's two branches, rising and falling temperature (400 s cycles: a rise,
    # a dwell, a fall, a dwell), the first half without falls; fitted on the first half
    # the falling branch's coefficient is undetermined (0): predicting the second half
    # with it, the rising branch's prediction (centred there) met the falls it does not
    # hold with the opposite sign and the check refused a true effect
    rng = np.random.default_rng(2)
    n, fs = 40000, 10.0
    t = np.arange(n) / fs
    phase = t % 400.0
    rise = (phase < 100.0).astype(float)
    fall = ((phase >= 200.0) & (phase < 300.0) & (t >= t[n // 2])).astype(float)
    X = np.column_stack((rise, fall))
    y = X @ np.array([0.3, 0.8]) + rng.standard_normal(n)
    stoch = SensorModel(fs, 0.0, Noise(N_dpsh=1.0 / 60.0 / np.sqrt(fs)), [])
    ctx = whittle_context(stoch, {}, t, np.ones(n, bool), y - y.mean())
    ok, note = _heldout_mean(ctx, X, ctx.wh.S)
    assert ok, note
    assert "second half: chi2 drop" in note and "first half: chi2 drop" in note


@pytest.mark.parametrize("kind", ["bias_step", "rate_ramp"])
def test_a_record_in_pieces_judges_an_effect_on_a_centred_residual(kind):
    # white noise and a 2 deg/h step (or ramp) in a record cut into 32 pieces; taken out as
    # it is (0 before the step), the effect left an offset over the valid samples, zeroed in
    # the gaps: gate-shaped low-frequency power read as a flicker excess 170x (ramp: 300x)
    # the white level at the slowest bin, so the fit's gain fell from 2654 to 492 and the
    # held-out check judged the ramp against that excess (expected chi2 drops 33, not 330)
    rng = np.random.default_rng(3)
    n, fs = 1 << 15, 10.0
    t = np.arange(n) / fs
    valid = (np.arange(n) // 1024) % 4 != 3   # 3 of every 4 blocks of 1024 samples kept
    effect = 2.0 * (np.arange(n) >= n // 3) if kind == "bias_step" else 2.0 * t / t[-1]
    y = effect + rng.standard_normal(n)
    stoch = SensorModel(fs, 0.0, Noise(N_dpsh=1.0 / 60.0 / np.sqrt(fs)), [])
    ctx = whittle_context(stoch, {}, t, valid, np.where(valid, y - y[valid].mean(), 0.0))
    c = (bias_step if kind == "bias_step" else rate_ramp)(ctx)
    assert c is not None and c.design is not None
    # the residual it leaves holds no flicker excess: judged against the calibrated PSD itself
    assert judged_psd(ctx, c) is ctx.wh.S
    assert c.gain == pytest.approx(ctx.wh.gls(ctx.wh.fft(c.design), ctx.Yf).chi2_gain)
    ok, note = _heldout(ctx, c)
    assert ok, note
    assert (ok, note) == _heldout_mean(ctx, c.design, ctx.wh.S)
    if kind == "rate_ramp":  # determined and visible in both halves
        drops = [float(x.split("chi2 drop ")[1].split()[0]) for x in note.split("; ")]
        assert min(drops) > 200.0, note
