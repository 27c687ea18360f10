"""Coefficient-jump events: judged against the run's own scatter, not the fit's intervals."""
from itertools import pairwise

import numpy as np

from fogmon.davar.jumps import JUMP_MIN_INDEPENDENT, JumpDetector, jump_threshold
from fogmon.davar.result import CONFIDENCE
from fogmon.pipeline.axis import JumpDetector as PipelineJumpDetector
from fogmon.sinks.base import COEFFICIENTS


class _C:
    def __init__(self, v, lo, hi, ok=True):
        self.value, self.lo, self.hi = np.array(v, float), np.array(lo, float), np.array(hi, float)
        self.identifiable = np.full(len(self.value), ok)


class _Fit:
    """N_dpsh as given (68.3 % intervals), the other terms not identifiable."""

    confidence = CONFIDENCE

    def __init__(self, n_vals, rel_half_width):
        k = len(n_vals)
        for name in COEFFICIENTS:
            setattr(self, name, _C(np.ones(k), np.zeros(k), 2 * np.ones(k), ok=False))
        v = np.asarray(n_vals, float)
        self.N_dpsh = _C(v, v * (1 - rel_half_width), v * (1 + rel_half_width))


def _overlapping_scatter(n, sd, hops_per_window, rng, df=3):
    """ln-coefficient series of windows overlapping by hops_per_window hops: a moving
    average of heavy-tailed (Student-t) per-hop contributions, scaled to sd."""
    e = rng.standard_t(df, size=n + hops_per_window)
    s = np.convolve(e, np.ones(hops_per_window), "valid")[:n]
    return sd * s / np.std(s)


def test_pipeline_uses_this_detector():
    assert PipelineJumpDetector is JumpDetector


def test_real_scatter_far_above_the_intervals_is_not_a_jump():
    # intervals of +-1 %, window-to-window scatter 7.6x that, heavy tails, windows
    # overlapping 8 hops: the previous detector (5 combined interval sigmas) fired here
    rng = np.random.default_rng(4)
    hop, w = 5.0, 40.0
    t = w + hop * np.arange(4000)
    v = 0.05 * np.exp(_overlapping_scatter(len(t), 0.076, 8, rng))
    assert JumpDetector(w).update(_Fit(v, 0.01), t) == []


def test_a_doubling_of_n_is_detected_once_right_after_it():
    rng = np.random.default_rng(5)
    hop, w = 5.0, 40.0
    t = w + hop * np.arange(1200)
    t_step = t[600]
    ln_v = _overlapping_scatter(len(t), 0.05, 8, rng)
    # a window straddling the step sees a mix; fully after it, 2x
    frac = np.clip((t - t_step) / w, 0.0, 1.0)
    v = 0.05 * np.exp(ln_v) * (1.0 + frac)
    ev = JumpDetector(w).update(_Fit(v, 0.01), t)
    assert len(ev) == 1 and ev[0].kind == "coef_jump" and ev[0].message.startswith("N_dpsh jumped")
    assert t_step < ev[0].t_s <= t_step + 2 * w
    assert "robust window-to-window scatter" in ev[0].message


def test_no_event_before_the_run_knows_its_own_scatter():
    # a 10x step early in the run: too few independent window pairs to judge it
    hop, w = 5.0, 40.0
    t = w + hop * np.arange(40)  # 195 s of differences: 1 + 195 / 80 < JUMP_MIN_INDEPENDENT
    v = np.where(t < 150, 1.0, 10.0)
    assert JumpDetector(w).update(_Fit(v, 0.01), t) == []


def test_threshold_falls_to_the_gaussian_one_with_many_pairs():
    assert jump_threshold(JUMP_MIN_INDEPENDENT - 1) == np.inf
    th = [jump_threshold(n) for n in (JUMP_MIN_INDEPENDENT, 20, 100, 10_000)]
    assert all(a > b for a, b in pairwise(th)) and 5.0 < th[-1] < 5.05
