"""The held-out check of a mean-type effect (selection._heldout_mean): a design column
one half does not hold predicts nothing there and is fitted freely in the other half."""
import numpy as np

from fogmon.explain.analysis import whittle_context
from fogmon.explain.selection import _heldout_mean
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
