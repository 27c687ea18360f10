"""The white-level candidates regress per-segment white levels on a channel: a channel
held at one value over the record is nothing to regress on, a switched one is."""
import numpy as np

from fogmon.explain.analysis import whittle_context
from fogmon.explain.candidates.white_level import vibration_noise
from fogmon.sim.model import Noise, SensorModel


def _ctx(vib_g: np.ndarray, level: np.ndarray):
    rng = np.random.default_rng(3)
    n, fs = len(vib_g), 10.0
    t = np.arange(n) / fs
    y = level * rng.standard_normal(n)
    stoch = SensorModel(fs, 0.0, Noise(N_dpsh=0.1 / 60.0 / np.sqrt(fs)), [])
    return whittle_context(stoch, {"vib_g": vib_g}, t, np.ones(n, bool), y)


def test_a_channel_held_at_one_value_is_no_regressor():
    vib = np.full(14720, 0.02)
    assert np.nanstd(vib) > 0  # float rounding: the channel "varies" by 3e-18 g
    # regressed on, the slope and intercept split the mean level (a rank-deficient fit) and
    # the slope's standard error is tiny: a real null record had t = 73.7
    assert vibration_noise(_ctx(vib, np.full(14720, 0.1))) is None


def test_a_switched_channel_that_drives_the_level_is_found():
    vib = np.where((np.arange(40000) // 4000) % 2 == 1, 2.0, 0.02)
    c = vibration_noise(_ctx(vib, np.where(vib > 1, 0.13, 0.1)))
    assert c is not None and c.gain > 100.0
