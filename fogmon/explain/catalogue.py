"""Candidate physics (effect kinds of docs/formats.md), each fitted to the current
residual and scored by a likelihood-ratio statistic ``gain`` with ``k`` free
parameters (scanned nonlinear ones included), so that forward selection can compare
them by BIC: accept when gain - k ln(n) > 0 and a held-out check passes.

- Mean-type effects (thermal_drift, periodic, glitches, bias_step, rate_ramp,
  scale_factor, warm_up) are linear in their amplitude-type coefficients: regressors
  come from the simulator's own effect functions with one coefficient set to 1, fitted
  by Whittle GLS (fitting.py) with the calibrated noise PSD; nonlinear parameters
  (period, step time, ramp start, settling time) by scans.
- markov and bandwidth change the noise PSD: Whittle likelihood of the residual's
  binned periodogram under the model PSD with and without the term.
- vibration_noise and temperature_noise change the white-noise level over time:
  per-segment white level (from the Allan variance at tau0) regressed on the segment
  mean of vib_g / temp_c.
"""
from __future__ import annotations

import copy
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats
from scipy.optimize import minimize, minimize_scalar
from scipy.stats import norm

from fogmon.davar.batch import oadev
from fogmon.davar.fit import IDENTIFY_Z, fit_avar
from fogmon.davar.theory import avar_terms_to_coefficients, coefficients_to_avar_terms
from fogmon.explain import detectors
from fogmon.explain.baseline import low_pass_index
from fogmon.explain.fitting import (
    BinnedPeriodogram,
    GlsFit,
    Whittle,
    avar1_of_psd,
    filter_gain2,
    lines_psd,
    low_band_flicker,
    markov_psd,
    model_psd,
    rfft_omega,
)
from fogmon.sim import effects as fx
from fogmon.sim.model import EFFECT_KINDS, OUTLIER_QUANTILE_PROBS, Effect, Noise, SensorModel, validate_effect
from fogmon.sim.noise import line_psd


@dataclass
class Context:
    """What every candidate sees: uniform time grid ``t_s`` (s), gap-filled aux channels,
    ``valid`` mask, sample rate, current residual ``y`` (deg/h, 0 where invalid), the
    current stochastic model, the calibrated Whittle GLS and the residual's DFT."""

    t_s: np.ndarray
    aux: dict
    valid: np.ndarray
    sample_rate_hz: float
    y: np.ndarray
    stoch: SensorModel
    wh: Whittle
    Yf: np.ndarray
    #: results shared by candidates within one round (the spike evidence)
    cache: dict = field(default_factory=dict, repr=False)

    @property
    def n(self) -> int:
        return len(self.t_s)

    @property
    def penalty(self) -> float:
        return math.log(max(int(self.valid.sum()), 2))


@dataclass
class Candidate:
    """A fitted effect: full parameters, standard errors of the fitted ones, the
    likelihood-ratio ``gain``, parameter count ``k``, the rate it removes from the
    residual (deg/h: a mean-type effect's deterministic rate, or an outlier population's
    replacements) and the design used (for the held-out check), plus evidence."""

    kind: str
    params: dict
    se: dict
    gain: float
    k: int
    evidence: str
    rate: np.ndarray | None = None
    design: np.ndarray | None = None
    heldout: Callable | None = field(default=None, repr=False)
    #: the white level N0 (deg/sqrt(h)) the stochastic model takes with this effect
    #: (a white-level regression's intercept), None: unchanged
    white_n0_dpsh: float | None = None
    #: the stochastic model this noise-type effect joins, its white-equivalent level
    #: refitted under it (vibration_lines: with_white_level, filtered_levels); None: the current one
    stoch_base: SensorModel | None = None
    #: every sample an ``outliers`` effect holds: times_s (s), amplitudes_dph (deg/h),
    #: abs_z (arrays; written to the outliers file, not into the report)
    listing: dict | None = field(default=None, repr=False)
    #: corrected IEEE-952 coefficients (the ``noise`` kind): replace the model's [noise]
    corrected_noise: Noise | None = None
    #: the gain a chance maximum of the candidate's own search exceeds with probability
    #: SEARCH_FALSE_ALARM (a periodic term's frequency search): the bar when above BIC's
    search_bar: float = 0.0

    @property
    def nature(self) -> str:
        return EFFECT_KINDS[self.kind].nature

    def bic_gain(self, penalty: float) -> float:
        """The gain above the bar: BIC's k ln n, or ``search_bar`` when that is higher."""
        return self.gain - max(self.k * penalty, self.search_bar)

    def effect(self) -> Effect:
        return validate_effect(self.kind, self.params, "fitted effect")


def unit_rate(kind: str, params: dict, ctx: Context) -> np.ndarray:
    """Rate (deg/h) of a mean-type effect with the given parameters on the context grid."""
    return fx.mean_rate_dph(validate_effect(kind, params, "candidate"), ctx.t_s, ctx.aux, ctx.sample_rate_hz)


def judged_gls(ctx: Context, Xf: np.ndarray) -> GlsFit:
    """Whittle GLS of the residual on the transformed design ``Xf``, judged against the
    noise its own residual shows at the slowest frequencies: refitted with the PSD
    raised there by that residual's significant flicker excess (low_band_flicker), so a
    drift, step or settling that is significant only against a model PSD extrapolated
    below its calibrated band - not against the sensor's own bias wander - loses that
    significance (its gain, coefficients and standard errors are the refit's)."""
    fit = ctx.wh.gls(Xf, ctx.Yf)
    S = low_band_flicker(ctx.wh.S, ctx.Yf - Xf.reshape(len(ctx.Yf), -1) @ fit.beta, ctx.n)
    return fit if S is ctx.wh.S else Whittle(S, ctx.n, ctx.valid).gls(Xf, ctx.Yf)


def _fmt(x: float, se: float) -> str:
    return f"{x:.4g} +- {se:.2g}"


# ---------------------------------------------------------------- mean-type
#: A periodic term's frequency search must find a line that chance (white residual,
#: the model true) beats with this probability only. BIC's 3 ln n alone is about the 2 %
#: point at 12000 samples (Baluev's law below; 6 of 300 white-noise records measured), and
#: the held-out check cannot refute such a peak: selected as the whole record's maximum,
#: it is a coherent sum of both halves, so each half predicts the other at its frequency.
SEARCH_FALSE_ALARM = 1e-3


def chance_line_gain(n: int, false_alarm: float) -> float:
    """The chi-square gain u that the largest of a continuous frequency search over the
    whole band of an n-sample record (two degrees of freedom per frequency) exceeds by
    chance with probability ``false_alarm``: Baluev (2008, MNRAS 385, 1279) for even
    sampling, P(max > u) = (n/2) sqrt(pi/3) sqrt(u/2) exp(-u/2), solved by fixed point."""
    u = 2.0 * math.log(n / 2.0 / false_alarm)
    for _ in range(20):
        u = 2.0 * math.log(n / 2.0 * math.sqrt(math.pi / 3.0) * math.sqrt(u / 2.0) / false_alarm)
    return u


def periodic(ctx: Context) -> Candidate | None:
    """Strongest line of the PSD-weighted periodogram (periods 3 samples .. duration/3),
    frequency refined by golden-section search on the GLS chi-square; its bar is at
    least :func:`chance_line_gain` at SEARCH_FALSE_ALARM."""
    n = ctx.n
    P = np.abs(ctx.Yf) ** 2 / (n * ctx.wh.S)
    P[:3] = 0.0
    P[-1] = 0.0
    k = int(np.argmax(P))
    t = ctx.t_s
    tr = t - t[0]

    def cols(f):
        return np.column_stack((np.sin(2 * np.pi * f * tr), np.cos(2 * np.pi * f * tr)))

    def g(f):
        return ctx.wh.gls(ctx.wh.fft(cols(f)), ctx.Yf).chi2_gain

    lo, hi = (k - 1) * ctx.sample_rate_hz / n, (k + 1) * ctx.sample_rate_hz / n
    r = (math.sqrt(5) - 1) / 2
    a, b = lo, hi
    c, d = b - r * (b - a), a + r * (b - a)
    gc, gd = g(c), g(d)
    for _ in range(14):
        if gc > gd:
            b, d, gd = d, c, gc
            c = b - r * (b - a)
            gc = g(c)
        else:
            a, c, gc = c, d, gd
            d = a + r * (b - a)
            gd = g(d)
    f, gf = (c, gc) if gc > gd else (d, gd)
    X = cols(f)
    h = 0.02 * ctx.sample_rate_hz / n
    curv = (2 * gf - g(f + h) - g(f - h)) / h ** 2
    fit = judged_gls(ctx, ctx.wh.fft(X))
    se_f = math.sqrt(2.0 / curv) if curv > 0 else float("nan")
    sa, ca = fit.beta
    amp = math.hypot(sa, ca)
    # A sin(2 pi f (t - t0) + ph0) = A sin(2 pi f t + phase) with phase = ph0 - 2 pi f t0
    phase = math.remainder(math.atan2(ca, sa) - 2 * np.pi * f * t[0], 2 * np.pi)
    period = 1.0 / f
    se_amp = float(np.sqrt(np.mean(fit.se ** 2)))
    params = {"period_s": period, "amplitude_dph": amp, "phase_rad": phase}
    ev = (f"periodogram line at {period:.6g} s (PSD-weighted power {P[k]:.3g}x the noise), "
          f"amplitude {_fmt(amp, se_amp)} deg/h")
    return Candidate("periodic", params, {"period_s": se_f / f ** 2, "amplitude_dph": se_amp,
                                          "phase_rad": se_amp / max(amp, 1e-300)},
                     fit.chi2_gain, 3, ev, X @ fit.beta, X, search_bar=chance_line_gain(n, SEARCH_FALSE_ALARM))


def bias_step(ctx: Context) -> Candidate | None:
    """Best single bias step over 1 %..99 % of the record (exact GLS scan)."""
    n = ctx.n
    n0, step, gain = detectors.step_scan(ctx.wh, ctx.Yf, int(0.01 * n), int(0.99 * n))
    X = (np.arange(n) >= n0).astype(float)[:, None]
    fit = judged_gls(ctx, ctx.wh.fft(X))
    t_step = float(ctx.t_s[n0] - 0.5 / ctx.sample_rate_hz)
    params = {"t_s": t_step, "step_dph": float(fit.beta[0])}
    ev = f"change-point scan: bias step of {_fmt(fit.beta[0], fit.se[0])} deg/h at t = {t_step:.6g} s"
    return Candidate("bias_step", params, {"step_dph": float(fit.se[0])}, fit.chi2_gain, 2, ev,
                     X @ fit.beta, X)


def _scan_1d(ctx: Context, make: Callable[[float], np.ndarray], grid: np.ndarray, refine: int = 8):
    """Best value of a nonlinear parameter on ``grid`` then on a finer grid around it."""
    gains = [ctx.wh.gls(ctx.wh.fft(make(v)), ctx.Yf).chi2_gain for v in grid]
    i = int(np.argmax(gains))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    fine = np.linspace(lo, hi, refine + 2)[1:-1]
    g2 = [ctx.wh.gls(ctx.wh.fft(make(v)), ctx.Yf).chi2_gain for v in fine]
    j = int(np.argmax(g2))
    return (fine[j], g2[j]) if g2[j] > gains[i] else (grid[i], gains[i])


def rate_ramp(ctx: Context) -> Candidate | None:
    """Linear rate drift starting at t0 (scanned over 0..90 % of the record)."""
    t = ctx.t_s
    T = t[-1] - t[0]

    def make(t0):
        return (np.maximum(t - t0, 0.0) / 3600.0)[:, None]

    t0, _ = _scan_1d(ctx, make, t[0] + T * np.linspace(0.0, 0.9, 16))
    X = make(t0)
    fit = judged_gls(ctx, ctx.wh.fft(X))
    params = {"slope_dphh": float(fit.beta[0]), "t0_s": float(t0)}
    ev = f"trend regression: rate slope {_fmt(fit.beta[0], fit.se[0])} deg/h^2 from t = {t0:.6g} s"
    return Candidate("rate_ramp", params, {"slope_dphh": float(fit.se[0])}, fit.chi2_gain, 2, ev, X @ fit.beta, X)


def warm_up(ctx: Context) -> Candidate | None:
    """Exponential settling from the start of the record, time constant scanned on a
    log grid from max(10 samples, 3 matched-filter lengths) to half the record."""
    t = ctx.t_s
    T = t[-1] - t[0]
    t0 = float(t[0])

    def make(ltau):
        return np.exp(-(t - t0) / math.exp(ltau))[:, None]

    # faster than a few matched-filter lengths it cannot be told from the record's ends
    # (the circular GLS joins them) or from a glitch
    tau_lo = max(10.0, 3.0 * detectors.kernel_length(ctx.wh)) / ctx.sample_rate_hz
    ltau, _ = _scan_1d(ctx, make, np.linspace(math.log(tau_lo), math.log(T / 2), 14))
    X = make(ltau)
    fit = judged_gls(ctx, ctx.wh.fft(X))
    tau = math.exp(ltau)
    params = {"amplitude_dph": float(fit.beta[0]), "tau_s": tau, "t0_s": t0}
    ev = f"settling fit: A = {_fmt(fit.beta[0], fit.se[0])} deg/h, tau = {tau:.4g} s from t = {t0:.6g} s"
    return Candidate("warm_up", params, {"amplitude_dph": float(fit.se[0])}, fit.chi2_gain, 2, ev, X @ fit.beta, X)


def scale_factor(ctx: Context) -> Candidate | None:
    """Scale-factor error on rot_dps: symmetric, and with asymmetry (better BIC wins)."""
    rot = ctx.aux.get("rot_dps")
    if rot is None or not np.nanstd(rot) > 0:
        return None
    c_ppm = unit_rate("scale_factor", {"ppm": 1.0, "asym_ppm": 0.0}, ctx)
    c_asym = unit_rate("scale_factor", {"ppm": 0.0, "asym_ppm": 1.0}, ctx)
    best = None
    for X, names in ((c_ppm[:, None], ("ppm",)), (np.column_stack((c_ppm, c_asym)), ("ppm", "asym_ppm"))):
        fit = ctx.wh.gls(ctx.wh.fft(X), ctx.Yf)
        if best is None or fit.chi2_gain - len(names) * ctx.penalty > best[0].chi2_gain - len(best[2]) * ctx.penalty:
            best = (fit, X, names)
    assert best is not None  # the loop ran at least once
    _, X, names = best
    fit = judged_gls(ctx, ctx.wh.fft(X))
    params = {"ppm": 0.0, "asym_ppm": 0.0}
    se = {}
    for i, nm in enumerate(names):
        params[nm] = float(fit.beta[i])
        se[nm] = float(fit.se[i])
    ev = ("regression on 3600 rot_dps: " + ", ".join(f"{nm} {_fmt(params[nm], se[nm])}" for nm in names)
          + f" (rotation rate std {np.nanstd(rot):.3g} deg/s)")
    return Candidate("scale_factor", params, se, fit.chi2_gain, len(names), ev, X @ fit.beta, X)


THERMAL_VARIANTS = {
    "K0 linear, K1, K2": (("k0_1",), ("k1",), ("k2",)),
    "K0 linear, K1/K2 by branch": (("k0_1",), ("k1_pos", "k1_neg"), ("k2_pos", "k2_neg")),
    "K0 quadratic, K1, K2": (("k0_1", "k0_2"), ("k1",), ("k2",)),
    "K0 quadratic, K1/K2 by branch": (("k0_1", "k0_2"), ("k1_pos", "k1_neg"), ("k2_pos", "k2_neg")),
}


def thermal_drift(ctx: Context) -> Candidate | None:
    """K0(T) + K1 dT/dt + K2 d2T/dt2 (the simulator's definition): four nested variants
    at each temperature smoothing of THERMAL_SMOOTHING (one more parameter when it is not
    the simulator's default), the best BIC wins."""
    temp = ctx.aux.get("temp_c")
    if temp is None or not np.nanstd(temp) > 0:
        return None
    best = None
    for smooth_s, diff_s in THERMAL_SMOOTHING:
        c = _thermal_drift(ctx, temp, smooth_s, diff_s)
        if best is None or c.bic_gain(ctx.penalty) > best.bic_gain(ctx.penalty):
            best = c
    return best


#: (smooth_s, diff_step_s) tried for the temperature derivatives (the simulator's
#: default first): a chamber's slow ramps need a longer smoothing than a drilling tool.
THERMAL_SMOOTHING = ((10.0, 1.0), (30.0, 10.0), (100.0, 30.0))


def _thermal_drift(ctx: Context, temp: np.ndarray, smooth_s: float, diff_s: float) -> Candidate:
    sm = {"smooth_s": smooth_s, "diff_step_s": diff_s}
    zero = {"k0_poly_dph": [], "k1_pos": 0.0, "k1_neg": 0.0, "k2_pos": 0.0, "k2_neg": 0.0, **sm}
    unit = {
        "k0_1": {**zero, "k0_poly_dph": [0.0, 1.0]}, "k0_2": {**zero, "k0_poly_dph": [0.0, 0.0, 1.0]},
        "k1_pos": {**zero, "k1_pos": 1.0}, "k1_neg": {**zero, "k1_neg": 1.0},
        "k2_pos": {**zero, "k2_pos": 1.0}, "k2_neg": {**zero, "k2_neg": 1.0},
    }
    cols = {k: unit_rate("thermal_drift", p, ctx) for k, p in unit.items()}
    cols["k1"] = cols["k1_pos"] + cols["k1_neg"]
    cols["k2"] = cols["k2_pos"] + cols["k2_neg"]
    fcols = {k: ctx.wh.fft(v) for k, v in cols.items()}
    best = None
    for label, groups in THERMAL_VARIANTS.items():
        names = [nm for g in groups for nm in g]
        fit = ctx.wh.gls(np.column_stack([fcols[nm] for nm in names]), ctx.Yf)
        score = fit.chi2_gain - len(names) * ctx.penalty
        if best is None or score > best[0]:
            best = (score, fit, names, label)
    assert best is not None  # the loop ran at least once
    _, _, names, label = best
    X = np.column_stack([cols[nm] for nm in names])
    fit = judged_gls(ctx, np.column_stack([fcols[nm] for nm in names]))
    v = dict(zip(names, fit.beta.tolist(), strict=True))
    s = dict(zip(names, fit.se.tolist(), strict=True))
    c1, c2 = v.get("k0_1", 0.0), v.get("k0_2", 0.0)
    rate = X @ fit.beta
    k0_part = X[:, :2] @ np.array([c1, c2]) if "k0_2" in v else X[:, 0] * c1
    c0 = -float(np.mean(k0_part[ctx.valid]))
    params = {"k0_poly_dph": [c0, c1, c2] if "k0_2" in v else [c0, c1],
              "k1_pos": v.get("k1_pos", v.get("k1", 0.0)), "k1_neg": v.get("k1_neg", v.get("k1", 0.0)),
              "k2_pos": v.get("k2_pos", v.get("k2", 0.0)), "k2_neg": v.get("k2_neg", v.get("k2", 0.0)), **sm}
    se = {"k0_c1": s.get("k0_1"), "k1_pos": s.get("k1_pos", s.get("k1")), "k1_neg": s.get("k1_neg", s.get("k1")),
          "k2_pos": s.get("k2_pos", s.get("k2")), "k2_neg": s.get("k2_neg", s.get("k2"))}
    if "k0_2" in s:
        se["k0_c2"] = s["k0_2"]
    pp = float(np.ptp(rate[ctx.valid]))
    ev = (f"regression on temperature and its derivatives ({label}; smoothing {smooth_s:g} s, "
          f"difference step {diff_s:g} s): "
          + ", ".join(f"{nm} {_fmt(v[nm], s[nm])}" for nm in names)
          + f"; predicted drift {pp:.3g} deg/h peak-to-peak over a {np.nanmax(temp) - np.nanmin(temp):.3g} degC span")
    extra = 0 if (smooth_s, diff_s) == THERMAL_SMOOTHING[0] else 1  # a smoothing moved from the default is fitted
    return Candidate("thermal_drift", params, se, fit.chi2_gain, len(names) + extra, ev, rate + c0, X)


def white_profile(model: SensorModel, ctx: Context) -> np.ndarray | None:
    """The model's own white-noise level over time relative to its RMS (1 on average),
    or None when it is constant (no white-level effect: vibration_noise,
    temperature_noise)."""
    if not any(EFFECT_KINDS[e.kind].nature == "white_level" for e in model.effects):
        return None
    level = np.full(ctx.n, model.noise.N_dpsh)
    for e in model.effects:
        if EFFECT_KINDS[e.kind].nature == "white_level":
            level = level + fx.white_level_dpsh(e, ctx.t_s, ctx.aux)
    level = np.maximum(level, 0.0)
    rms = float(np.sqrt(np.mean(level ** 2)))
    return np.maximum(level / rms, 1e-3) if rms > 0 else None


def spike_scan(ctx: Context, y: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """GLS amplitude (deg/h) and robust z of a one-sample spike at every sample
    (detectors.spike_scan) of the residual (``y``, default the context's). When the
    model's white level varies in time (vibration- or temperature-driven ARW), the
    residual is first divided by that level, so a sample that is large only because the
    model itself is noisier there is not a spike."""
    sep = detectors.kernel_length(ctx.wh)
    block = max(4096, 64 * sep)
    prof = white_profile(ctx.stoch, ctx)
    if prof is None:
        return detectors.spike_scan(ctx.wh, ctx.Yf if y is None else ctx.wh.fft(y), block=block)
    amp, z = detectors.spike_scan(ctx.wh, ctx.wh.fft((ctx.y if y is None else y) / prof), block=block)
    return amp * prof, z


@dataclass
class SpikeEvidence:
    """The spike test of one residual and its two descriptions: ``glitch_idx`` (every
    sample beyond the Bonferroni threshold, local maxima ``sep`` apart) with the BIC
    gain of listing them one by one, and the contaminated-Gaussian ``law`` of all z
    (None: no tail) with the BIC gain of describing them as a population."""

    amp: np.ndarray
    z: np.ndarray
    sep: int
    thr: float
    glitch_idx: np.ndarray
    bic_glitches: float
    law: detectors.Contamination | None
    bic_population: float
    #: why the spikes are not an outlier population ("" when they are)
    not_population: str = ""

    @property
    def population(self) -> bool:
        """Outliers are a population when that description has the larger BIC gain and
        the tail is one of rare, far, time-homogeneous outliers (``not_population``)."""
        return not self.not_population and self.bic_population > max(self.bic_glitches, 0.0)


#: parameters an outlier population carries in the model: rate, positive fraction and
#: the amplitude quantiles (what its BIC pays for)
POPULATION_K = 2 + len(OUTLIER_QUANTILE_PROBS)


def spike_evidence(ctx: Context) -> SpikeEvidence:
    """Spike test of the context's residual and its glitch/population descriptions
    (computed once per context). The population's likelihood gain is the
    contaminated-Gaussian fit over every tested z, divided by ``sep`` (a spike lights up
    about ``sep`` correlated z values when the noise is coloured, which a sum over samples
    would count ``sep`` times)."""
    if "spikes" in ctx.cache:
        return ctx.cache["spikes"]
    sep = detectors.kernel_length(ctx.wh)
    amp, z = spike_scan(ctx)
    nv = int(ctx.valid.sum())
    thr = detectors.bonferroni_z(nv)
    idx = detectors.find_spikes(z, thr, min_sep=sep)
    bic_g = float(np.sum(z[idx] ** 2)) - 2 * len(idx) * ctx.penalty if len(idx) else 0.0
    tested = ctx.valid & (z != 0.0)
    law = detectors.fit_contamination(z[tested])
    bic_p = law.gain / sep - POPULATION_K * ctx.penalty if law is not None else 0.0
    ev = SpikeEvidence(amp, z, sep, thr, idx, bic_g, law, bic_p, _not_population(law, z, tested))
    ctx.cache["spikes"] = ev
    return ev


#: an outlier population's contaminated samples spread at least this many times wider
#: than the clean noise (a narrower excess is a heavier-shouldered noise or a noise
#: level varying in time, which the map reports)
OUTLIER_MIN_SD_RATIO = 3.0
#: blocks of the record in which the outliers' occurrence must look homogeneous
OUTLIER_BLOCKS = 16


def _not_population(law: detectors.Contamination | None, z: np.ndarray, tested: np.ndarray) -> str:
    """Why the tail of the spike statistic is not a population of rare outliers ("" when
    it is): no tail; a contaminated part not far from the clean noise (spread under
    OUTLIER_MIN_SD_RATIO x) or not a minority (over 10 %); or outliers not occurring
    at one rate over the record (counts beyond the even-odds point in OUTLIER_BLOCKS
    blocks over-dispersed against Poisson at 1 %: bursts of a higher noise level, not a
    rare shock process)."""
    if law is None:
        return "no tail beyond |z| = 4"
    if law.s < OUTLIER_MIN_SD_RATIO or law.eps > 0.1:
        return (f"the tail is a broad shoulder ({100 * law.eps:.3g} % of samples {law.s:.3g}x wider than the rest), "
                f"not rare far outliers")
    cut = law.z_even
    edges = np.linspace(0, len(z), OUTLIER_BLOCKS + 1).astype(np.int64)
    cs = np.concatenate(([0], np.cumsum(tested & (np.abs(z) > cut))))[edges]
    cv = np.concatenate(([0], np.cumsum(tested)))[edges]
    c, v = np.diff(cs), np.diff(cv)
    e = c.sum() * v / max(v.sum(), 1)
    use = e > 0
    disp = float(np.sum((c[use] - e[use]) ** 2 / e[use]))
    dof = int(use.sum()) - 1
    if dof > 0 and stats.chi2.sf(disp, dof) < 0.01:
        return (f"the outliers do not occur at one rate: their counts in {OUTLIER_BLOCKS} blocks scatter "
                f"{disp / dof:.3g}x as much as a Poisson process's (p = {stats.chi2.sf(disp, dof):.2g}): bursts "
                f"of a higher noise level, not a rare shock process")
    return ""


def glitches(ctx: Context) -> Candidate | None:
    """Isolated spikes: GLS matched filter at every sample, robust (MAD) scale, the
    model's own white-level profile divided out, Bonferroni threshold over all samples
    (1 % family-wise); every one listed (when an outlier population describes them better,
    :func:`outliers` has the larger BIC gain and is tried first)."""
    ev = spike_evidence(ctx)
    idx = ev.glitch_idx
    if not len(idx):
        return None
    amp, z, thr = ev.amp, ev.z, ev.thr
    times = (ctx.t_s[idx]).tolist()
    amps = amp[idx].tolist()
    rate = np.zeros(ctx.n)
    rate[idx] = amp[idx]
    gain = float(np.sum(z[idx] ** 2))
    zmax = float(np.max(np.abs(z[idx])))
    pop = (f"; not an outlier population: {ev.not_population}" if ev.not_population else
           f"; as an outlier population the BIC gain would be {ev.bic_population:.1f} (vs {ev.bic_glitches:.1f} "
           f"listed one by one)")
    text = (f"robust spike test: {len(idx)} sample(s) beyond |z| = {thr:.2f} (1 % family-wise over "
            f"{int(ctx.valid.sum())} samples), largest |z| = {zmax:.1f}, amplitudes "
            f"{np.min(np.abs(amps)):.3g}..{np.max(np.abs(amps)):.3g} deg/h{pop}")
    se = {"amplitudes_dph": float(1.0 / math.sqrt(np.sum(ctx.wh.w)))}
    return Candidate("glitches", {"times_s": times, "amplitudes_dph": amps}, se, gain, 2 * len(idx), text,
                     rate, None)


#: the outlier search repeats the spike scan on the cleaned residual at most this often
#: (a cluster of outlying samples is found peak first, then its neighbours)
OUTLIER_PASSES = 4
#: seed of the noise drawn for the replaced outlier samples (reproducible reports)
OUTLIER_FILL_SEED = 20261126


def outliers(ctx: Context) -> Candidate | None:
    """A heavy-tailed outlier population (kind ``outliers``): when the contaminated-
    Gaussian description of the spike test beats listing glitches one by one (BIC), every
    sample more likely contaminated than clean (|z| beyond the mixture's even-odds point,
    or the Bonferroni threshold if lower) is an outlier; the scan is repeated on the
    cleaned residual (clusters). Each outlier is replaced by the GLS interpolation from
    its neighbours plus a draw of the model's conditional noise there (so the rest keeps
    the model's noise statistics). Rate, |amplitude| quantiles and the mixture are the
    effect's parameters; ``times_s``/``amplitudes_dph``/``abs_z`` go to the outliers file."""
    if any(e.kind == "outliers" for e in ctx.stoch.effects):
        return None
    ev = spike_evidence(ctx)
    if not ev.population:
        return None
    law = ev.law
    assert law is not None  # a population needs a fitted law (bic_population is 0 without one)
    z_cut = min(law.z_even, ev.thr)
    se = np.where(ev.z != 0.0, np.abs(ev.amp / np.where(ev.z != 0.0, ev.z, 1.0)), 0.0)
    se = np.where(se > 0, se, float(np.median(se[se > 0])) if (se > 0).any() else 0.0)
    removed, first_z = _outlier_passes(ctx, ev, z_cut)
    idx = np.flatnonzero(first_z > 0)
    if not len(idx):
        return None
    a = removed[idx]
    fill = np.random.default_rng([OUTLIER_FILL_SEED, len(idx)]).standard_normal(len(idx)) * se[idx]
    rate = np.zeros(ctx.n)
    rate[idx] = a - fill
    hours = int(ctx.valid.sum()) / ctx.sample_rate_hz / 3600.0
    nv = int(ctx.valid.sum())
    q = np.quantile(np.abs(a), OUTLIER_QUANTILE_PROBS)
    params = {"rate_per_h": len(idx) / hours, "amplitude_quantiles_dph": q.tolist(),
              "quantile_probs": list(OUTLIER_QUANTILE_PROBS), "positive_fraction": float(np.mean(a > 0)),
              "count": len(idx), "rate_per_sample": len(idx) / nv,
              "contamination_fraction": law.eps, "contamination_sd_ratio": law.s}
    text = (f"robust spike test: {len(idx)} outlier sample(s) (|z| beyond {z_cut:.2f}, where a sample is as likely "
            f"contaminated as clean) among {nv} samples: {len(idx) / hours:.4g} per hour, {len(idx) / nv:.3g} per "
            f"sample; |amplitude| median {q[3]:.3g} deg/h, 90 % {q[5]:.3g}, 99 % {q[6]:.3g}, largest {q[-1]:.3g} "
            f"deg/h; contaminated-Gaussian fit of the spike statistic: {100 * law.eps:.3g} % of samples with "
            f"{law.s:.3g}x the clean spread. A population, not glitches: BIC gain {ev.bic_population:.1f} as a "
            f"rate and amplitude distribution ({POPULATION_K} parameters) vs {ev.bic_glitches:.1f} listing "
            f"{len(ev.glitch_idx)} glitch(es) one by one; outliers replaced by the interpolation from their "
            f"neighbours plus the model's conditional noise")
    return Candidate("outliers", params, {"rate_per_h": math.sqrt(len(idx)) / hours}, law.gain / ev.sep,
                     POPULATION_K, text, rate, None, functools.partial(_population_heldout, ctx, ev),
                     listing={"times_s": ctx.t_s[idx], "amplitudes_dph": a, "abs_z": first_z[idx]})


def _outlier_passes(ctx: Context, ev, z_cut: float) -> tuple[np.ndarray, np.ndarray]:
    """The spike scan repeated on the cleaned residual (clusters), at most OUTLIER_PASSES
    times: per sample the amplitude removed (deg/h) and the |z| it was first found at (0:
    not an outlier)."""
    removed = np.zeros(ctx.n)
    first_z = np.zeros(ctx.n)
    amp, z = ev.amp, ev.z
    y = ctx.y.copy()
    for _ in range(OUTLIER_PASSES):
        new = detectors.find_spikes(z, z_cut, min_sep=ev.sep)
        new = new[first_z[new] == 0.0]
        if not len(new):
            break
        removed[new] += amp[new]
        first_z[new] = np.abs(z[new])
        y[new] -= amp[new]
        amp, z = spike_scan(ctx, np.where(ctx.valid, y, 0.0))
    return removed, first_z


def _population_heldout(ctx: Context, ev) -> list[tuple[float, float]]:
    """The held-out check of an outlier population: the contamination law fitted on one
    half of the record, its log-likelihood gain on the other half against the gain it
    claims there (per independent spike statistic), both ways."""
    tested = ctx.valid & (ev.z != 0.0)
    half = np.arange(ctx.n) < ctx.n // 2
    res = []
    for fit_m, test_m in ((half, ~half), (~half, half)):
        law_f = detectors.fit_contamination(ev.z[tested & fit_m])
        zt = ev.z[tested & test_m]
        if law_f is None:
            res.append((0.0, 0.0))
            continue
        share = len(zt) / max(int((tested & fit_m).sum()), 1)
        res.append((law_f.loglik_gain(zt) / ev.sep, law_f.gain / ev.sep * share))
    return res


MEAN_CANDIDATES = {
    "periodic": periodic, "bias_step": bias_step, "rate_ramp": rate_ramp, "warm_up": warm_up,
    "scale_factor": scale_factor, "thermal_drift": thermal_drift, "glitches": glitches, "outliers": outliers,
}


# ---------------------------------------------------------------- noise-type
def _periodogram(ctx: Context, part: slice = slice(None)) -> BinnedPeriodogram:
    """Binned periodogram of the residual (or of ``part`` of it)."""
    y = np.where(ctx.valid[part], ctx.y[part], 0.0)
    return BinnedPeriodogram(np.fft.rfft(y), len(y))


def _passband(ctx: Context, bp: BinnedPeriodogram) -> BinnedPeriodogram:
    """``bp`` over the model's pass band (``in_passband``)."""
    keep = in_passband(ctx.stoch, bp.omega)
    if keep.all():
        return bp
    band = copy.copy(bp)
    band.count, band.I, band.k, band.omega = bp.count[keep], bp.I[keep], bp.k[keep], bp.omega[keep]
    return band


def white_rms_dpsh(model: SensorModel, ctx: Context) -> float:
    """RMS over the record of the white level N(t) = N0 + white-level effects (deg/sqrt(h))."""
    return white_level_rms_dpsh(model, ctx.t_s, ctx.aux)


def white_level_rms_dpsh(model: SensorModel, t_s: np.ndarray, aux: dict) -> float:
    """``white_rms_dpsh`` from the sample times ``t_s`` (s) and aux channels alone."""
    level = np.full(len(t_s), model.noise.N_dpsh)
    for e in model.effects:
        if EFFECT_KINDS[e.kind].nature == "white_level":
            level = level + fx.white_level_dpsh(e, t_s, aux)
    return float(np.sqrt(np.mean(np.maximum(level, 0.0) ** 2)))


def _stoch_psd(ctx: Context, bp: BinnedPeriodogram) -> np.ndarray:
    return model_psd(ctx.stoch, bp.omega, ctx.n, white_rms_dpsh(ctx.stoch, ctx))


#: the calibrated Whittle GLS of the mean-type candidates and the spike test
#: (explainer._whittle), the markov fit and the lines' proposals keep the frequencies
#: where the model's ``bandwidth`` filters pass at least this share of the power (|H|^2, -20 dB)
PASSBAND_MIN_GAIN2 = 0.01


def passband_gain2(model: SensorModel, omega: np.ndarray) -> np.ndarray:
    """|H|^2 of the model's ``bandwidth`` filters at ``omega`` (rad/sample; 1 without a
    filter); the pass band is where it is at least PASSBAND_MIN_GAIN2. Beyond it the
    model PSD is orders of magnitude below its pass-band level (floored in the fits),
    so a likelihood there measures the filter's exact shape (on a real sensor the
    fitted filter is not the real one), not a term under it; and a term there is
    attenuated by the filter as much as the noise."""
    G = np.ones(len(omega))
    for e in model.effects:
        if e.kind == "bandwidth":
            G = G * filter_gain2(e.params, float(model.sample_rate_hz), omega)
    return G


def in_passband(model: SensorModel, omega: np.ndarray) -> np.ndarray:
    """The frequencies ``omega`` (rad/sample) where the model's ``bandwidth`` filters pass
    at least PASSBAND_MIN_GAIN2 of the power (all of them without a filter)."""
    return passband_gain2(model, omega) >= PASSBAND_MIN_GAIN2


def markov(ctx: Context) -> Candidate | None:
    """Gauss-Markov term: Whittle likelihood over a log grid of correlation times
    (5 samples .. duration/20), variance by Newton steps (>= 0). A best fit at the
    longest correlation time is refused (a drift, left to the mean-type effects), and at
    the shortest (a white-noise level change, left to the white-level effects). Under a
    ``bandwidth`` filter the term is filtered like the rest of the rate (sim
    BandwidthFilter) and fitted over the filter's pass band (``_passband``): a
    correlation time of 5 samples or more puts less than 1/(2 pi 5 x 0.45)^2 = 0.5 % of
    its low-frequency PSD near Nyquist, so the bins left out carry next to nothing on it."""
    bp = _passband(ctx, _periodogram(ctx))
    G = passband_gain2(ctx.stoch, bp.omega)
    S0 = _stoch_psd(ctx, bp)
    floor = LEAKAGE_FLOOR * float(np.median(S0))
    d0 = bp.deviance(S0, floor)
    T = ctx.n / ctx.sample_rate_hz
    best = None
    grid = np.geomspace(5.0 / ctx.sample_rate_hz, T / 20.0, 36)
    for tc in grid:
        P = G * markov_psd(bp.omega, ctx.sample_rate_hz, 1.0, tc)
        v = _newton_variance(bp, S0, P)
        if v <= 0:
            continue
        g = d0 - bp.deviance(S0 + v * P, floor)
        if best is None or g > best[0]:
            best = (g, tc, v)
    if best is None or best[1] >= grid[-1] or best[1] <= grid[0]:
        return None  # at the grid's ends it is a drift or a white-noise level, not a Gauss-Markov term
    g, tc, v = best
    sigma = math.sqrt(v)
    # se of sigma from the curvature in v
    P = G * markov_psd(bp.omega, ctx.sample_rate_hz, 1.0, tc)
    S = S0 + v * P
    info = float(np.sum(bp.count * P ** 2 / S ** 2))
    se_sigma = math.sqrt(1.0 / info) / (2 * sigma) if info > 0 else float("nan")
    band = ("" if G.min() == 1.0 else
            f" over 0-{bp.omega[-1] * ctx.sample_rate_hz / (2 * math.pi):.4g} Hz (the bandwidth filter's pass band)")
    ev = (f"Whittle fit of the residual spectrum{band}: Gauss-Markov sigma {_fmt(sigma, se_sigma)} deg/h, "
          f"correlation time {tc:.4g} s (ADEV hump {0.618 * sigma:.3g} deg/h near tau = {1.89 * tc:.3g} s)")
    return Candidate("markov", {"tau_c_s": float(tc), "sigma_dph": sigma}, {"sigma_dph": se_sigma}, g, 2, ev)


def _newton_variance(bp: BinnedPeriodogram, S0: np.ndarray, P: np.ndarray) -> float:
    v = 0.0
    for _ in range(30):
        S = S0 + v * P
        g1 = float(np.sum(bp.count * P * (1.0 / S - bp.I / S ** 2)))
        g2 = float(np.sum(bp.count * P ** 2 * (-1.0 / S ** 2 + 2.0 * bp.I / S ** 3)))
        if g2 <= 0:
            break
        v_new = max(v - g1 / g2, 0.0)
        if abs(v_new - v) <= 1e-9 * max(v_new, 1e-300):
            v = v_new
            break
        v = v_new
    return v


#: PSD floor relative to the median model PSD in the spectral fits (periodogram leakage)
LEAKAGE_FLOOR = 1e-4


def bandwidth(ctx: Context) -> Candidate | None:
    """The sensor's own low-pass: Butterworth order 1..4, cutoff on a log grid from
    fs/500 to 0.49 fs, by Whittle likelihood of the residual spectrum."""
    if any(e.kind == "bandwidth" for e in ctx.stoch.effects):
        return None
    bp = _periodogram(ctx)
    S0 = _stoch_psd(ctx, bp)
    floor = LEAKAGE_FLOOR * float(np.median(S0))
    d0 = bp.deviance(S0, floor)

    def gain(order, fc):
        p = {"cutoff_hz": float(fc), "order": int(order), "taps": []}
        return d0 - bp.deviance(S0 * filter_gain2(p, ctx.sample_rate_hz, bp.omega), floor), p

    best = None
    grid = np.geomspace(ctx.sample_rate_hz / 500.0, 0.49 * ctx.sample_rate_hz, 48)
    for order in (1, 2, 3, 4):
        gains = [gain(order, fc)[0] for fc in grid]
        i = int(np.argmax(gains))
        a, b = math.log(grid[max(i - 1, 0)]), math.log(grid[min(i + 1, len(grid) - 1)])
        r = (math.sqrt(5) - 1) / 2
        for _ in range(30):  # golden section on log cutoff
            c, d = b - r * (b - a), a + r * (b - a)
            if gain(order, math.exp(c))[0] > gain(order, math.exp(d))[0]:
                b = d
            else:
                a = c
        g, p = gain(order, math.exp((a + b) / 2))
        if best is None or g > best[0]:
            best = (g, p)
    assert best is not None  # the loop ran at least once
    g, p = best
    ev = (f"Whittle fit of the residual spectrum: high frequencies fall below the model, as a "
          f"Butterworth low-pass of order {p['order']} at {p['cutoff_hz']:.4g} Hz")
    return Candidate("bandwidth", p, {}, g, 2, ev)


#: the noise levels refitted under vibration lines when the model holds a bandwidth
#: filter (filtered_levels): IEEE-952 name, unit
FILTERED_LEVELS = (("N_dpsh", "deg/sqrt(h)"), ("Q_arcsec", "arcsec"))
#: a refitted noise level is at most this many times its previous value
LEVEL_MAX_RATIO = 2.0


def filtered_levels(model: SensorModel, bp: BinnedPeriodogram, extra: np.ndarray | float,
                    floor: float) -> tuple[SensorModel, list[str]] | None:
    """``model`` (holding a ``bandwidth`` filter) with its N and Q (those it has)
    refitted jointly by the Whittle likelihood of ``bp`` under its PSD plus ``extra``
    (PSD at the bins, e.g. vibration lines): a baseline splits them on the shortest
    taus' ADEV, where the filter acts, before the filter is in the model, and the
    filter acts on both (sim BandwidthFilter). Returns (the model, the names refitted),
    or None without such a filter, without N and Q, or with white-level effects (they
    set N)."""
    nz = model.noise
    names = [nm for nm, _ in FILTERED_LEVELS if getattr(nz, nm) > 0]
    if (not names or not any(e.kind == "bandwidth" for e in model.effects)
            or any(EFFECT_KINDS[e.kind].nature == "white_level" for e in model.effects)):
        return None
    n = bp.n
    other = model_psd(replace(model, noise=replace(nz, **{nm: 0.0 for nm in names})), bp.omega, n)
    filters = [e for e in model.effects if e.kind == "bandwidth"]
    units = np.array([model_psd(SensorModel(model.sample_rate_hz, 0.0, replace(Noise(0.0, 0.0, 0.0, 0.0, 0.0),
                                                                               **{nm: getattr(nz, nm)}), filters),
                                bp.omega, n) for nm in names])

    def dev(x):  # x: variances relative to the current ones
        S = np.maximum(other + extra + x @ units, max(floor, 1e-300))
        r = bp.count * (1.0 / S - bp.I / S ** 2)
        return float(np.sum(bp.count * (np.log(S) + bp.I / S))), units @ r

    r = minimize(dev, np.ones(len(names)), jac=True, method="L-BFGS-B",
                 bounds=[(0.0, LEVEL_MAX_RATIO ** 2)] * len(names))
    return replace(model, noise=replace(nz, **{nm: getattr(nz, nm) * math.sqrt(x) for nm, x in
                                              zip(names, r.x, strict=True)})), names


def _levels_text(old: SensorModel, new: SensorModel, names: list[str]) -> str:
    """``names`` (FILTERED_LEVELS) with their values in ``old`` and ``new``, units."""
    units = dict(FILTERED_LEVELS)
    return ", ".join(f"{nm.split('_')[0]} {getattr(old.noise, nm):.4g} -> {getattr(new.noise, nm):.4g} {units[nm]}"
                     for nm in names)


def _segment_levels(ctx: Context, seg: int):
    """Per-segment white level N (deg/sqrt(h)) from the Allan variance at tau0, and
    segment index boundaries."""
    y = np.where(ctx.valid, ctx.y, np.nan)
    d = np.diff(y)
    nseg = (len(d)) // seg
    d = d[: nseg * seg].reshape(nseg, seg)
    with np.errstate(invalid="ignore"):
        av1 = np.nanmean(d ** 2, axis=1) / 2.0
    w = rfft_omega(4096)
    stoch_noN = _replace_white(ctx.stoch, 0.0)
    c_other = avar1_of_psd(model_psd(stoch_noN, w, ctx.n), 4096)
    c_white = avar1_of_psd(model_psd(_replace_white(ctx.stoch, 1.0, drop_other=True), w, ctx.n), 4096)
    lev = np.sqrt(np.maximum(av1 - c_other, 0.0) / c_white)
    return lev, nseg


def _replace_white(model: SensorModel, N: float, drop_other: bool = False) -> SensorModel:
    nz = model.noise
    noise = Noise(0.0, N, 0.0, 0.0, 0.0) if drop_other else Noise(nz.Q_arcsec, N, nz.B_dph, nz.K_dphsh, nz.R_dphh)
    eff = [e for e in model.effects
           if e.kind == "bandwidth" or (not drop_other and e.kind in ("markov", "lowpass_noise", "vibration_lines"))]
    return SensorModel(model.sample_rate_hz, model.bias_dph, noise, eff)


def _ols(x: np.ndarray, y: np.ndarray):
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    X = np.column_stack((np.ones(len(x)), x))
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ beta
    s2 = float(r @ r) / max(len(x) - 2, 1)
    cov = s2 * np.linalg.pinv(X.T @ X)
    return beta, np.sqrt(np.diag(cov)), s2


def _white_level(ctx: Context, kind: str, channel: str) -> Candidate | None:
    a = ctx.aux.get(channel)
    if a is None or not np.nanstd(a) > 0 or any(e.kind == kind for e in ctx.stoch.effects):
        return None
    seg = max(16, ctx.n // 2000)
    lev, nseg = _segment_levels(ctx, seg)
    if nseg < 20:
        return None
    x = np.nanmean(a[: nseg * seg].reshape(nseg, seg), axis=1)
    beta, se, s2 = _ols(x, lev)
    tstat = beta[1] / se[1] if se[1] > 0 else 0.0
    N0 = ctx.stoch.noise.N_dpsh
    if kind == "vibration_noise":
        if beta[1] <= 0:
            return None
        params = {"n_gain_dpsh_per_g": float(beta[1])}
        sep = {"n_gain_dpsh_per_g": float(se[1])}
        what = f"N = {beta[0]:.4g} + {_fmt(beta[1], se[1])} * vib_g deg/sqrt(h)"
    else:
        t_ref = (N0 - beta[0]) / beta[1] if beta[1] != 0 else float(np.nanmean(a))
        params = {"n_gain_dpsh_per_c": float(beta[1]), "t_ref_c": float(t_ref)}
        sep = {"n_gain_dpsh_per_c": float(se[1])}
        what = f"N = {beta[0]:.4g} + {_fmt(beta[1], se[1])} * temp_c deg/sqrt(h)"

    def heldout():
        h = nseg // 2
        res = []
        for fit_sl, test_sl in ((slice(0, h), slice(h, nseg)), (slice(h, nseg), slice(0, h))):
            bf, _, _ = _ols(x[fit_sl], lev[fit_sl])
            xt, lt = x[test_sl], lev[test_sl]
            ok = np.isfinite(xt) & np.isfinite(lt)
            base = lt[ok] - np.mean(lt[ok])
            pred = lt[ok] - (bf[0] + bf[1] * xt[ok])
            pred = pred - np.mean(pred)
            res.append((float(base @ base - pred @ pred) / s2, float(np.var(xt[ok]) * ok.sum() * bf[1] ** 2 / s2)))
        return res

    ev = (f"white level per {seg / ctx.sample_rate_hz:.3g} s segment (ADEV at tau0) regressed on the segment mean of "
          f"{channel}: {what}, t = {tstat:.1f} over {nseg} segments")
    n0 = max(float(beta[0]), 0.0) if kind == "vibration_noise" else None  # N = N0 + gain vib_g
    return Candidate(kind, params, sep, float(tstat ** 2), 1, ev, heldout=heldout, white_n0_dpsh=n0)


def vibration_noise(ctx: Context) -> Candidate | None:
    return _white_level(ctx, "vibration_noise", "vib_g")


def temperature_noise(ctx: Context) -> Candidate | None:
    return _white_level(ctx, "temperature_noise", "temp_c")


# ---------------------------------------------------------------- vibration_lines
#: a line is kept when it lowers the Whittle deviance by more than this many BIC
#: penalties ln n (it has 3 parameters: centre, bandwidth, rms)
LINE_PARAMS = 3
#: lines fitted per vibration_lines candidate (the strongest first; the fit's cost grows
#: with the lines; weaker lines are proposed again to a second vibration_lines round, and
#: the verdict's line hint lists every line the residual still holds)
MAX_LINES = 10
#: a fitted line's quality factor centre / bandwidth is at least this (the G ring's secondary
#: microseism is a real band of Q = 1.5)
LINE_MIN_Q = 1.0


def _whitened(ctx: Context) -> np.ndarray:
    """The residual divided by the model PSD in the frequency domain (white where the
    model fits, a peak where a line is missing; not the calibrated PSD, whose octave
    bands would absorb part of a broad line)."""
    S = model_psd(ctx.stoch, rfft_omega(ctx.n), ctx.n, white_rms_dpsh(ctx.stoch, ctx))
    S = np.maximum(S, LEAKAGE_FLOOR * float(np.median(S[1:])))  # a filter's zero: no division by 0
    S[0] = np.inf
    return np.fft.irfft(ctx.Yf / np.sqrt(S), ctx.n)


def _fit_line(bp: BinnedPeriodogram, S: np.ndarray, floor: float, sample_rate_hz: float, n: int, f0: float,
              bw0: float) -> tuple[float, tuple[float, float, float]]:
    """One line (centre Hz, rms deg/h, -3 dB bandwidth Hz) on top of the PSD ``S`` at the
    periodogram's bins, started at (f0, bw0): Nelder-Mead on the Whittle deviance over
    (centre, ln bandwidth, ln variance); returns (deviance drop, line)."""
    d0 = bp.deviance(S, floor)
    near = np.abs(bp.omega * sample_rate_hz / (2 * np.pi) - f0) <= 5 * bw0
    var0 = max(float(np.sum(bp.count[near] * np.maximum(bp.I[near] - S[near], 0.0)) / n), 1e-30)
    bw_lo, nyq = 2.0 * sample_rate_hz / n, sample_rate_hz / 2

    def unpack(x):
        f = float(x[0])
        bw = float(min(max(math.exp(x[1]), bw_lo), f / LINE_MIN_Q))  # narrowband: Q = f / bw
        return f, math.sqrt(math.exp(x[2])), bw

    def dev(x):
        f, sig, bw = unpack(x)
        if not (f - bw / 2 > 0 and f + bw / 2 < nyq):
            return d0 + 1e9
        return bp.deviance(S + line_psd(bp.omega, sample_rate_hz, f, sig, bw), floor)

    x0 = np.array([f0, math.log(bw0), math.log(var0)])
    simplex = np.array([x0, x0 + [0.3 * bw0, 0, 0], x0 + [0, 0.7, 0], x0 + [0, 0, 0.7]])
    r = minimize(dev, x0, method="Nelder-Mead", options={"initial_simplex": simplex, "xatol": 1e-4,
                                                         "fatol": 0.05, "maxfev": 600})
    return d0 - float(r.fun), unpack(r.x)


def fit_lines(bp: BinnedPeriodogram, S0: np.ndarray, sample_rate_hz: float, n: int, starts: list[tuple[float, float]],
              penalty: float) -> tuple[float, list[tuple[float, float, float]]]:
    """Lines fitted one after the other from ``starts`` ((centre Hz, start bandwidth Hz)),
    each on top of the ones kept before it and kept when its deviance drop exceeds
    LINE_PARAMS ln n and it is narrowband (its bandwidth not at the Q = LINE_MIN_Q limit);
    returns (total deviance drop, lines (centre, rms, bandwidth))."""
    floor = LEAKAGE_FLOOR * float(np.median(S0))
    S = S0.copy()
    lines: list[tuple[float, float, float]] = []
    for f0, bw0 in starts:
        if any(abs(f0 - f) < max(bw, bw0) for f, _, bw in lines):
            continue
        g, line = _fit_line(bp, S, floor, sample_rate_hz, n, f0, bw0)
        # a fit that runs into the widest band allowed (Q = LINE_MIN_Q) is broadband
        # spectral shape (a filter's slope), not a line: not kept
        if g > LINE_PARAMS * penalty and line[2] < 0.98 * line[0] / LINE_MIN_Q:
            lines.append(line)
            S = S + line_psd(bp.omega, sample_rate_hz, line[0], line[1], line[2])
    return bp.deviance(S0, floor) - bp.deviance(S, floor), sorted(lines)


def _low_pass_index(model: SensorModel) -> int | None:
    """Index in ``model.effects`` of its white noise through a low-pass (``low_pass_index``)
    when the model has no N of its own (that term is then its white-equivalent level),
    else None."""
    return None if model.noise.N_dpsh > 0 else low_pass_index(model)


def with_white_level(model: SensorModel, level: float) -> SensorModel:
    """``model`` with its white-equivalent level set to ``level``: N (deg/sqrt(h)), or
    the sigma (deg/h) of its low-pass term when it has one instead (_low_pass_index)."""
    i = _low_pass_index(model)
    if i is None:
        return replace(model, noise=replace(model.noise, N_dpsh=level))
    eff = list(model.effects)
    eff[i] = Effect(eff[i].kind, {**eff[i].params, "sigma_dph": level}, eff[i].axes)
    return replace(model, effects=eff)


def _white_parts(ctx: Context, omega: np.ndarray, n: int):
    """(PSD of the model without its white-equivalent noise, PSD of that noise at level
    1, its current level) at ``omega``: N and unit white noise through the model's
    filters, or - without N - the low-pass term's sigma and its unit PSD; None when
    white-level effects set N or the model has neither."""
    st = ctx.stoch
    if any(EFFECT_KINDS[e.kind].nature == "white_level" for e in st.effects):
        return None
    i = _low_pass_index(st)
    if i is None:
        if st.noise.N_dpsh <= 0:
            return None
        return (model_psd(_replace_white(st, 0.0), omega, n),
                model_psd(_replace_white(st, 1.0, drop_other=True), omega, n), st.noise.N_dpsh)
    one = with_white_level(st, 1.0)
    unit = SensorModel(st.sample_rate_hz, 0.0, Noise(0.0, 0.0, 0.0, 0.0, 0.0),
                       [e for j, e in enumerate(one.effects) if j == i or e.kind == "bandwidth"])
    return (model_psd(with_white_level(st, 0.0), omega, n), model_psd(unit, omega, n),
            float(st.effects[i].params["sigma_dph"]))


def lines_and_white(ctx: Context, bp: BinnedPeriodogram, n: int, starts: list[tuple[float, float]]):
    """fit_lines on the model PSD, then the model's white-equivalent level (N, or the
    sigma of its low-pass term, _white_parts; N and Q under a bandwidth filter,
    filtered_levels) refitted under the lines (their power was counted in it before:
    the lines' skirts as white noise, or lines near Nyquist in a baseline's low-pass
    level) by the same Whittle likelihood. Returns (deviance drop, lines, the stochastic
    model with the refitted levels or None when not refitted, the levels refitted)."""
    sample_rate_hz = ctx.sample_rate_hz
    S0 = model_psd(ctx.stoch, bp.omega, n, white_rms_dpsh(ctx.stoch, ctx))
    floor = LEAKAGE_FLOOR * float(np.median(S0))
    _, lines = fit_lines(bp, S0, sample_rate_hz, n, starts, ctx.penalty)
    parts = _white_parts(ctx, bp.omega, n)
    if not lines:
        return 0.0, lines, None, 0
    S_l = _lines_at(lines, sample_rate_hz, bp.omega)
    d0 = bp.deviance(S0, floor)
    both = filtered_levels(ctx.stoch, bp, S_l, floor)
    if both is not None:
        return d0 - bp.deviance(model_psd(both[0], bp.omega, n) + S_l, floor), lines, both[0], len(both[1])
    if parts is None:
        return d0 - bp.deviance(S0 + S_l, floor), lines, None, 0
    other, unit, level0 = parts
    r = minimize_scalar(lambda v: bp.deviance(other + v * v * unit + S_l, floor),
                        bounds=(0.0, LEVEL_MAX_RATIO * level0), method="bounded", options={"xatol": 1e-4 * level0})
    return d0 - float(r.fun), lines, with_white_level(ctx.stoch, float(r.x)), 1


def _lines_at(lines: list[tuple[float, float, float]], sample_rate_hz: float, omega: np.ndarray) -> np.ndarray:
    """PSD at ``omega`` of fitted lines (centre Hz, rms deg/h, bandwidth Hz)."""
    return lines_psd({"freq_hz": [x[0] for x in lines], "sigma_dph": [x[1] for x in lines],
                      "bandwidth_hz": [x[2] for x in lines]}, sample_rate_hz, omega)


def _lines_heldout(ctx: Context, lines: list) -> list[tuple[float, float]]:
    """The held-out check of vibration lines: refitted on one half of the record from the
    fitted (centre, rms, bandwidth) ``lines``, the deviance they gain on the other half,
    and on the half they were refitted on, both ways."""
    sample_rate_hz, n = ctx.sample_rate_hz, ctx.n
    out = []
    h = n // 2
    halves = (slice(0, h), slice(h, 2 * h))
    bps = [_periodogram(ctx, sl) for sl in halves]
    wr = white_rms_dpsh(ctx.stoch, ctx)
    for a, b in ((0, 1), (1, 0)):
        ga, la, refit, _ = lines_and_white(ctx, bps[a], h, [(f, bw) for f, _, bw in lines])
        S0b = model_psd(ctx.stoch, bps[b].omega, h, wr)
        S1b = S0b if refit is None else model_psd(refit, bps[b].omega, h, white_rms_dpsh(refit, ctx))
        fl = LEAKAGE_FLOOR * float(np.median(S0b))
        pb = {"freq_hz": [x[0] for x in la], "sigma_dph": [x[1] for x in la], "bandwidth_hz": [x[2] for x in la]}
        gb = (
            bps[b].deviance(S0b, fl) - bps[b].deviance(S1b + lines_psd(pb, sample_rate_hz, bps[b].omega), fl)
            if la
            else 0.0
        )
        out.append((float(gb), float(ga)))
    return out  # (tested on the second half, on the first)


def vibration_lines(ctx: Context) -> Candidate | None:
    """Narrowband random vibration: lines proposed by detectors.spectral_lines on the
    residual whitened by the model PSD (between max(50 / duration, fs / 1000) and
    0.49 fs or the top of the model's pass band, in_passband), each then fitted
    (centre, -3 dB bandwidth, rms) by the Whittle likelihood of the residual's binned
    periodogram under the model PSD plus the band-pass lines, and the model's
    white-equivalent level (N, or a baseline's low-pass sigma; N and Q under a
    bandwidth filter) refitted under them (lines_and_white). The removable estimate is
    the Wiener smoother S_lines / (S_model + S_lines) applied to the residual's DFT."""
    sample_rate_hz, n = ctx.sample_rate_hz, ctx.n
    T = n / sample_rate_hz
    f_lo = max(50.0 / T, sample_rate_hz / 1000.0)
    bp = _periodogram(ctx)
    props = detectors.spectral_lines(
        np.where(ctx.valid, _whitened(ctx), np.nan),
        sample_rate_hz,
        f_lo,
        min(0.49, float(bp.omega[in_passband(ctx.stoch, bp.omega)][-1]) / (2 * np.pi)) * sample_rate_hz,
        min_ratio=LINE_MIN_RATIO,
    )[:MAX_LINES]
    if not props:
        return None
    res = (
        8 * sample_rate_hz / (2 ** math.ceil(math.log2(8 * sample_rate_hz / f_lo)))
    )  # a few Welch bins: the start bandwidth
    starts = [(f, max(res, 4 * sample_rate_hz / n)) for f, _ in props]
    gain, lines, refit, levels = lines_and_white(ctx, bp, n, starts)
    if not lines:
        return None
    params = {"freq_hz": [ln[0] for ln in lines], "sigma_dph": [ln[1] for ln in lines],
              "bandwidth_hz": [ln[2] for ln in lines]}
    w = rfft_omega(n)
    S_l = lines_psd(params, sample_rate_hz, w)
    base = ctx.stoch if refit is None else refit
    S_all = model_psd(base, w, n, white_rms_dpsh(base, ctx)) + S_l
    with np.errstate(divide="ignore", invalid="ignore"):  # DC (inf) and a filter's zeros (0)
        wiener = np.where(np.isfinite(S_all) & (S_all > 0), S_l / S_all, 0.0)
    est = np.fft.irfft(wiener * ctx.Yf, n)

    ev = ("Whittle fit of the residual spectrum: narrowband random vibration, "
          + "; ".join(f"{f:.4g} Hz (-3 dB bandwidth {bw:.3g} Hz, rms {sig:.3g} deg/h, ADEV hump near "
                      f"tau = {0.371 / f:.3g} s)" for f, sig, bw in lines)
          + " - band-limited noise, not one coherent sinusoid"
          + ("" if refit is None else "; " + _refit_text(ctx.stoch, refit)))
    return Candidate("vibration_lines", params, {}, float(gain), LINE_PARAMS * len(lines) + levels, ev,
                     rate=est, heldout=functools.partial(_lines_heldout, ctx, lines), stoch_base=refit)


def _refit_text(old: SensorModel, new: SensorModel) -> str:
    """What a refit of the white-equivalent level under lines changed (with_white_level)."""
    i = _low_pass_index(old)
    if new.noise.Q_arcsec != old.noise.Q_arcsec:  # filtered_levels
        names = [nm for nm, _ in FILTERED_LEVELS if getattr(new.noise, nm) != getattr(old.noise, nm)]
        return f"{_levels_text(old, new, names)} refitted under the lines and the filter"
    if i is None:
        return f"white level refitted under the lines: N {old.noise.N_dpsh:.4g} -> {new.noise.N_dpsh:.4g} deg/sqrt(h)"
    return (f"the low-pass white noise's level refitted under the lines (their power was in it): sigma "
            f"{old.effects[i].params['sigma_dph']:.4g} -> {new.effects[i].params['sigma_dph']:.4g} deg/h")


# ---------------------------------------------------------------- noise (coefficients)
#: two-sided confidence of the intervals of the noise effect (and of "differs")
NOISE_CONFIDENCE = 0.95
#: the coefficients the noise effect may correct (index into theory.POWERS); R is the
#: deterministic part's (a wrong R is a rate_ramp effect)
NOISE_TERMS = ("Q_arcsec", "N_dpsh", "B_dph", "K_dphsh")


#: fixed-point steps refining the corrected terms (the first correction is exact when
#: the terms do not interact in the fit)
NOISE_ITERATIONS = 2


def expected_avar(S: np.ndarray, n: int, m: np.ndarray) -> np.ndarray:
    """Allan variance ((deg/h)^2) at averaging factors ``m`` of a process with PSD ``S``
    at the rfft bins of an n-sample record: sum over the circle of
    S 2 sin^4(m w / 2) / (m^2 sin^2(w / 2)) / n (the DC bin left out)."""
    w = rfft_omega(n)[1:]
    Sf = np.where(np.isfinite(S[1:]), S[1:], 0.0)
    mult = np.full(len(w), 2.0)
    if n % 2 == 0:
        mult[-1] = 1.0
    s2 = np.sin(w / 2.0) ** 2
    return np.array([float(np.sum(mult * Sf * 2.0 * np.sin(mm * w / 2.0) ** 4 / (mm * mm * s2)) / n)
                     for mm in np.asarray(m, dtype=float)])


def fit_coefficients(y: np.ndarray, valid: np.ndarray, stoch: SensorModel, sample_rate_hz: float, white_dpsh: float):
    """Corrected IEEE-952 coefficients of ``stoch`` from the residual ``y`` (deg/h):
    davar.fit.fit_avar (robust, octave taus, 95 % one-sided upper limits) on the
    residual's overlapping ADEV and on the ADEV the current stochastic model predicts
    for the same record (expected_avar of its PSD); each avar term is corrected by the
    difference, A = A_model + (A_recording - A_expected), so that what the model's other
    terms (flicker approximation, Gauss-Markov, lines, filters, white-level effects) do
    to the fit cancels. Returns {name: (value, lo, hi, model value)} in coefficient
    units for the terms whose model value lies outside the recording's NOISE_CONFIDENCE
    interval (identified terms: A +- z se; others: 0 .. the 95 % upper limit), refined by
    NOISE_ITERATIONS fixed-point steps A += A_recording - A_predicted(A) (the terms
    interact in the fit), or None when the ADEV cannot be fitted."""
    n = len(y)
    r = oadev(np.where(valid, y, np.nan), sample_rate_hz, "octave", valid=valid)
    a, se, _, up = fit_avar(r.tau_s, r.adev_dph ** 2, r.m, r.n_terms, n, "all")
    S = model_psd(stoch, rfft_omega(n), n, white_dpsh)
    ae, _, _, _ = fit_avar(r.tau_s, expected_avar(S, n, r.m), r.m, r.n_terms, n, "none")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(ae))):
        return None
    nz = stoch.noise
    am = coefficients_to_avar_terms(nz.Q_arcsec, nz.N_dpsh, nz.B_dph, nz.K_dphsh, 0.0)
    z = float(norm.ppf(0.5 + NOISE_CONFIDENCE / 2.0))
    ident = a - IDENTIFY_Z * se > 0
    lo = np.where(ident, np.maximum(a - z * se, 0.0), 0.0)
    hi = np.where(ident, a + z * se, np.maximum(up, a))
    differ = np.array([not (lo[i] <= ae[i] <= hi[i]) and np.isfinite(hi[i]) for i in range(len(NOISE_TERMS))]
                      + [False])
    if not differ.any():
        return {}
    A = am.copy()
    A[differ] = np.maximum(am + a - ae, 0.0)[differ]
    conv = avar_terms_to_coefficients
    for _ in range(NOISE_ITERATIONS):  # the terms interact in such a fit (flicker's short-tau excess
        c = conv(A)                    # reads partly as N): fit(predicted ADEV of A) -> fit(recording)
        noise = Noise(Q_arcsec=c[0], N_dpsh=c[1], B_dph=c[2], K_dphsh=c[3], R_dphh=0.0)
        new = SensorModel(stoch.sample_rate_hz, 0.0, noise, stoch.effects)
        Sk = model_psd(new, rfft_omega(n), n, white_dpsh - nz.N_dpsh + float(c[1]))
        ak, _, _, _ = fit_avar(r.tau_s, expected_avar(Sk, n, r.m), r.m, r.n_terms, n, "none")
        if not np.all(np.isfinite(ak)):
            break
        A[differ] = np.maximum(A + a - ak, 0.0)[differ]
    shift = A - a
    out = {}
    for i, name in enumerate(NOISE_TERMS):
        # a term flagged only through another one's error (B too small reads partly as N)
        # is left alone when its model value is inside its own corrected interval
        if not differ[i] or max(lo[i] + shift[i], 0.0) <= am[i] <= hi[i] + shift[i]:
            continue
        vals = [max(x + shift[i], 0.0) for x in (a[i], lo[i], hi[i])]
        coef = [float(conv(np.eye(5)[i] * v)[i]) for v in vals]
        out[name] = (*coef, float(getattr(nz, name)))
    return out


def _corrected(stoch: SensorModel, fit: dict) -> SensorModel:
    return SensorModel(stoch.sample_rate_hz, stoch.bias_dph,
                       replace(stoch.noise, **{k: v[0] for k, v in fit.items()}), stoch.effects, stoch.meta)


NOISE_UNIT = {"Q_arcsec": "arcsec", "N_dpsh": "deg/sqrt(h)", "B_dph": "deg/h", "K_dphsh": "deg/h/sqrt(h)"}


def noise_text(name: str, value: float, lo: float, hi: float, model_value: float) -> str:
    """"your N is 0.041 deg/sqrt(h) [0.039, 0.043], not 0.030" (an unidentified term:
    "below <hi>")."""
    u = NOISE_UNIT[name]
    sym = name.split("_")[0]
    if lo <= 0 and value <= 0:
        return f"your {sym} is below {hi:.3g} {u} (95 % upper limit), not {model_value:.3g}"
    return f"your {sym} is {value:.3g} {u} [{lo:.3g}, {hi:.3g}], not {model_value:.3g}"


def noise(ctx: Context) -> Candidate | None:
    """The model's own Q, N, B, K are wrong (fit_coefficients): the terms whose model
    value lies outside the recording's 95 % interval, corrected; scored by the Whittle
    likelihood of the residual's binned periodogram under the model PSD with and without
    the correction (one parameter per corrected term)."""
    wr = white_rms_dpsh(ctx.stoch, ctx)
    fit = fit_coefficients(ctx.y, ctx.valid, ctx.stoch, ctx.sample_rate_hz, wr)
    if not fit:
        return None
    bp = _periodogram(ctx)
    new = _corrected(ctx.stoch, fit)
    S0 = _stoch_psd(ctx, bp)
    S1 = model_psd(new, bp.omega, ctx.n, white_rms_dpsh(new, ctx))
    floor = LEAKAGE_FLOOR * float(np.median(S0))
    gain = bp.deviance(S0, floor) - bp.deviance(S1, floor)
    params = {}
    for k, (v, lo, hi, _) in fit.items():
        params.update({k: v, f"{k}_lo": lo, f"{k}_hi": hi})
    se = {k: (hi - lo) / (2 * 1.959964) for k, (v, lo, hi, _) in fit.items()}

    def heldout():
        out = []
        h = ctx.n // 2
        halves = (slice(0, h), slice(h, 2 * h))
        for a, b in ((0, 1), (1, 0)):
            fa = fit_coefficients(ctx.y[halves[a]], ctx.valid[halves[a]], ctx.stoch, ctx.sample_rate_hz, wr)
            bpb, bpa = _periodogram(ctx, halves[b]), _periodogram(ctx, halves[a])
            if not fa:
                out.append((0.0, 0.0))
                continue
            na = _corrected(ctx.stoch, fa)
            gains = []
            for bb in (bpb, bpa):
                s0 = model_psd(ctx.stoch, bb.omega, h, wr)
                s1 = model_psd(na, bb.omega, h, white_rms_dpsh(na, ctx))
                fl = LEAKAGE_FLOOR * float(np.median(s0))
                gains.append(bb.deviance(s0, fl) - bb.deviance(s1, fl))
            out.append((float(gains[0]), float(gains[1])))
        return out  # (tested on the second half, on the first)

    ev = ("robust IEEE-952 fit of the residual's Allan deviation against the one the model predicts "
          "(95 % intervals): " + "; ".join(noise_text(k, *v) for k, v in fit.items()))
    return Candidate("noise", params, se, float(gain), len(fit), ev, heldout=heldout,
                     corrected_noise=new.noise)


#: a whitened-periodogram peak this many times the band median proposes a line
LINE_MIN_RATIO = 4.0


NOISE_CANDIDATES = {"markov": markov, "bandwidth": bandwidth, "vibration_noise": vibration_noise,
                    "temperature_noise": temperature_noise, "vibration_lines": vibration_lines, "noise": noise}
