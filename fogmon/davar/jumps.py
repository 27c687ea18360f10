"""Coefficient-jump events over the windows of a DADEV noise fit.

A coefficient's newest estimate is compared with its estimate in the latest window that
shares no samples with it: d = ln(new / reference). Whether d is a jump is judged against
the run's own window-to-window scatter, not the fit's intervals (real records scatter
several times more than a window's interval says): the median and the MAD of every
earlier d of that coefficient (robust to heavy tails and to the jumps themselves), with
the fit's combined interval as a floor. Consecutive d share data (windows overlap, and d
spans two windows), so the run holds only about span / (2 x window) independent d; the
threshold is the Student-t quantile with the MAD's degrees of freedom for that many
(0.37 n - 1, its efficiency) at the two-sided tail probability of JUMP_Z Gaussian sigma,
so a short run does not over-trust a scale it has barely seen. No event before
JUMP_MIN_INDEPENDENT independent differences.
"""
from __future__ import annotations

import math
from collections import deque
from statistics import NormalDist

import numpy as np

from fogmon.block import Event
from fogmon.davar.fit import NAMES
from fogmon.units import coefficient_unit

JUMP_Z = 5.0
"""Gaussian-equivalent size of a jump: two-sided tail 2 Phi(-5) = 5.7e-7 per independent
window pair and coefficient."""
JUMP_MIN_INDEPENDENT = 8
"""Independent window-pair differences a coefficient needs before it can jump."""
_MAD_EFFICIENCY = 0.37  # a MAD of n Gaussian values is worth a standard deviation of 0.37 n
_MAD_SD = 1.4826        # standard deviation / MAD for Gaussian data
_P_JUMP = math.erfc(JUMP_Z / math.sqrt(2.0))  # 2 Phi(-JUMP_Z)


def jump_threshold(n_independent: float) -> float:
    """Threshold on |d - median| / (1.4826 MAD) for a MAD of ``n_independent``
    independent differences: Student-t quantile at tail probability 2 Phi(-JUMP_Z),
    0.37 n - 1 degrees of freedom (inf when fewer than JUMP_MIN_INDEPENDENT)."""
    if n_independent < JUMP_MIN_INDEPENDENT:
        return math.inf
    from scipy.special import stdtrit  # imported here: scipy costs start-up time

    return -float(stdtrit(_MAD_EFFICIENCY * n_independent - 1.0, _P_JUMP / 2.0))


class JumpDetector:
    """Coefficient-jump events (module docstring) for the windows of one run, window
    length ``window_s`` (s). At most one event per coefficient per window length."""

    def __init__(self, window_s: float):
        self.window_s = window_s
        self._hist: deque[tuple[float, dict]] = deque()  # (t_end_s, {name: (value, lo, hi, rel_se)})
        self._diffs: dict[str, tuple[list[float], list[float]]] = {}  # name -> (t_end_s, d)
        self._last_event: dict[str, float] = {}

    def update(self, fit, t_end_s: np.ndarray) -> list[Event]:
        """Events of the windows of ``fit`` (a NoiseFit over windows) ending at ``t_end_s`` (s)."""
        z_conf = NormalDist().inv_cdf(0.5 + fit.confidence / 2)
        cols = {name: [np.atleast_1d(np.asarray(getattr(getattr(fit, name), a), dtype=np.float64))
                       for a in ("value", "lo", "hi", "identifiable")] for name in NAMES}
        out = []
        for i, t in enumerate(np.asarray(t_end_s, dtype=np.float64)):
            cur = {}
            for name, (v, lo, hi, ok) in cols.items():
                if ok[i] and v[i] > 0 and np.isfinite(lo[i]) and np.isfinite(hi[i]):
                    cur[name] = (v[i], lo[i], hi[i], (hi[i] - lo[i]) / (2.0 * z_conf * v[i]))
            h = self._hist
            while len(h) > 1 and h[1][0] <= t - self.window_s:
                h.popleft()
            ref = h[0] if h and h[0][0] <= t - self.window_s else (math.nan, {})  # none yet: nothing compared
            for name, (v, lo, hi, rse) in cur.items():
                if name not in ref[1]:
                    continue
                rv, rlo, rhi, rrse = ref[1][name]
                d = math.log(v / rv)
                ts, ds = self._diffs.setdefault(name, ([], []))
                if ds:
                    n_ind = 1.0 + (ts[-1] - ts[0]) / (2.0 * self.window_s)
                    med = float(np.median(ds))
                    scale = max(_MAD_SD * float(np.median(np.abs(np.asarray(ds) - med))), math.hypot(rse, rrse))
                    z = abs(d - med) / max(scale, 1e-300)
                    if z > jump_threshold(n_ind) and t - self._last_event.get(name, -math.inf) >= self.window_s:
                        self._last_event[name] = float(t)
                        out.append(Event(float(t), "coef_jump",
                                         f"{name} jumped from {rv:.4g} [{rlo:.4g}, {rhi:.4g}] to {v:.4g} [{lo:.4g}, "
                                         f"{hi:.4g}] {coefficient_unit(name)} (x{v / rv:.3g}: {z:.1f} x the run's "
                                         f"robust window-to-window scatter {scale:.3g} in ln, threshold "
                                         f"{jump_threshold(n_ind):.1f} for {n_ind:.0f} independent differences; "
                                         f"windows ending at {ref[0]:.1f} s and {t:.1f} s)"))
                ts.append(float(t))
                ds.append(d)
            self._hist.append((float(t), cur))
        return out
