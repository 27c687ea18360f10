"""The null of the mean-type candidates' likelihood ratios when the model's noise is not
stationary (issue 28; docs/explain.md, "Mean-type candidates under a rate random walk").

A mean-type candidate (periodic, bias_step, rate_ramp, warm_up, scale_factor,
thermal_drift) is a Whittle GLS fit: its chi-square gain has its nominal law, and
BIC's bar its meaning, when the residual is stationary Gaussian noise of the model's
PSD. A rate random walk (K) is not stationary: its chance excursions look like steps,
ramps and settlings far more often than the K part of the PSD says (a 100 Hz,
2^17-sample record of issue 28's five-term model beats BIC's bar with a chance step in
about half of its simulations); so does flicker where it holds the record's longest
taus (N, B, R at 2 Hz over 6 h named a chance ramp or step in 2 of 25 records), and a
Gauss-Markov term whose correlation time is not short beside the record (tau_c 5000 s
in 1 h at 10 Hz: 9 of 16). So when the model holds K, or its Allan variance at a quarter
of the record falls slower than tau^-1/2 (``calibrated_kinds``),
each mean-type kind's gain is also measured on every bootstrap replicate (the same
draws as the map's null: the model's whole stochastic part, K, B, Q, N and the
noise-type effects), as its excess over the candidate's own search bar (0 for a kind
without a search; a periodic term's bar is its octave's, so the excess puts a line in
any octave on one scale), and its bar (``Candidate.chance_bar``) is that search bar
raised by the excess a Gumbel law fitted to those excesses exceeds with probability
alpha / (number of such kinds): the model's own processes then name a chance step, ramp,
settling or line no more often than that. Otherwise the GLS's law is taken to hold and nothing
is simulated (no cost: a 1e6-sample record whose flicker holds 23 % there took 41.8 s
instead of 8.3 with its bars simulated).

A bar fitted to B replicate gains has the same Monte Carlo error as the map's
threshold, larger at its alpha / 6 level (5.4 sd / sqrt(B) against 3.9 at the map's
1 %), so a candidate whose gain lies near its bar is decided by the draw as much as by
the data; the sequential test (bootstrap.settled, selection.bars_undecided) draws more
replicates then, as it does for a borderline region: ``scan_bars`` gives each bar's
standard error."""
from __future__ import annotations

import numpy as np

from fogmon.explain.analysis import whittle_context
from fogmon.explain.candidates import CANDIDATES
from fogmon.explain.fitting import model_psd
from fogmon.explain.mismatch import Gumbel
from fogmon.sim.model import EFFECT_KINDS, SensorModel

#: fewer finite null gains than this give no bar (a Gumbel fit needs a spread)
MIN_GAINS = 8
#: the log-log slope of the model's Allan variance at a quarter of the record from which
#: its bars are simulated too: flicker holding half of it beside white noise (the slope
#: is minus white noise's share), a Gauss-Markov term not short beside the record
LONG_MEMORY_SLOPE = -0.5


def calibrated_kinds(stoch: SensorModel, duration_s: float) -> tuple[str, ...]:
    """The candidate kinds whose bar comes from the replicates: the mean-type ones when
    ``stoch`` holds a rate random walk (K > 0), or when its Allan variance at a quarter
    of the record's ``duration_s`` (the longest tau its fit uses) falls slower than
    tau^LONG_MEMORY_SLOPE (``allan_slope``: dominant flicker, a Gauss-Markov term whose
    correlation time is not short beside the record), else none."""
    n = int(round(duration_s * float(stoch.sample_rate_hz))) + 1
    if not (stoch.noise.K_dphsh > 0 or allan_slope(stoch, duration_s / 4.0, n) >= LONG_MEMORY_SLOPE):
        return ()
    return tuple(k for k in CANDIDATES if EFFECT_KINDS[k].nature == "mean")


def allan_slope(stoch: SensorModel, tau_s: float, n: int) -> float:
    """d ln(Allan variance) / d ln(tau) at ``tau_s`` (s) of the stochastic model ``stoch``
    over an ``n``-sample record, from its PSD (``fitting.model_psd``: the IEEE-952 terms,
    Gauss-Markov and low-pass noise, vibration lines, bandwidth filters) through the Allan
    filter of m-sample averages, 2 sin^4(m w / 2) / (m sin(w / 2))^2 (sin^4 at its mean
    3 / 8 beyond 20 of its periods), half an octave either side of ``tau_s``: -2 for Q,
    -1 for N, 0 for flicker, +1 for K, for a Gauss-Markov term +1 well below its
    correlation time and -1 well above it."""
    fs = float(stoch.sample_rate_hz)
    avar = []
    for m in (tau_s * fs * 2.0 ** -0.25, tau_s * fs * 2.0 ** 0.25):
        m = max(m, 1.0)
        edge = min(40.0 * np.pi / m, np.pi)
        total = 0.0
        for w, sin4 in ((np.geomspace(1e-4 / m, edge, 4000), None), (np.geomspace(edge, np.pi, 400), 0.375)):
            if w[0] >= w[-1]:
                continue
            kernel = 2.0 * (np.sin(m * w / 2.0) ** 4 if sin4 is None else sin4) / (m * np.sin(w / 2.0)) ** 2
            total += np.trapezoid(model_psd(stoch, w, n) * kernel * w, np.log(w))
        avar.append(total)
    return float(np.log(avar[1] / avar[0]) / np.log(2.0 ** 0.5))


class ScanGains:
    """The chi-square gain of each of ``kinds`` less its own search bar
    (``Candidate.search_bar``), fitted to a replicate of the stochastic model ``stoch``
    (deg/h, NaN where not valid), prepared like explain's residual (mean over the valid
    samples removed, 0 where not valid); NaN for a kind not applicable. Picklable (runs
    in the bootstrap's workers)."""

    def __init__(self, stoch: SensorModel, t_s: np.ndarray, aux: dict, valid: np.ndarray, kinds: tuple[str, ...]):
        self.stoch, self.t_s, self.aux, self.valid, self.kinds = stoch, t_s, aux, valid, kinds

    def __call__(self, r: np.ndarray) -> dict[str, float]:
        v = self.valid
        y = np.where(v, r - np.mean(r[v]), 0.0)
        ctx = whittle_context(self.stoch, self.aux, self.t_s, v, y, copy=False)
        out = {}
        for kind in self.kinds:
            c = CANDIDATES[kind](ctx)
            out[kind] = float(c.gain - c.search_bar) if c is not None else float("nan")
        return out


def scan_bars(gains: list[dict[str, float]], alpha: float) -> tuple[dict[str, float], dict[str, float]]:
    """kind -> the excess gain the replicates' ``gains`` (one dict per replicate) exceed with
    probability alpha / (number of kinds), from a Gumbel law fitted to them; and kind ->
    that bar's Monte Carlo standard error (mismatch.Gumbel.isf_se)."""
    kinds = sorted({k for g in gains for k in g})
    bars, se = {}, {}
    for kind in kinds:
        x = np.array([g.get(kind, np.nan) for g in gains], dtype=float)
        x = x[np.isfinite(x)]
        if len(x) >= MIN_GAINS:
            law = Gumbel.fit(x)
            bars[kind], se[kind] = law.isf(alpha / len(kinds)), law.isf_se(alpha / len(kinds))
    return bars, se
