"""Mean-type candidates: periodic, bias_step, rate_ramp, warm_up, scale_factor and
thermal_drift, linear in their amplitude-type coefficients (regressors from the
simulator's own effect functions with one coefficient set to 1, fitted by Whittle GLS
with the calibrated noise PSD), their nonlinear parameters (period, step time, ramp
start, settling time, temperature smoothing) by scans."""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.stats import chi2

from fogmon.explain import detectors
from fogmon.explain.candidates.base import (
    Candidate,
    Context,
    estimate_text,
    exact_cov_fit,
    exact_law,
    judged_gls,
    judged_whittle,
    unit_rate,
    varies,
)
from fogmon.explain.fitting import Coarse, coarse_block, weighted_products

#: A periodic term's frequency search must find a line that chance (the residual the
#: model's noise, the model true) beats with this probability only. BIC's 3 ln n alone is
#: about the 2 % point at 12000 samples (Baluev's law below; 6 of 300 white-noise records
#: measured), and the held-out check cannot refute such a peak: selected as the whole
#: record's maximum, it is a coherent sum of both halves, so each half predicts the other
#: at its frequency.
SEARCH_FALSE_ALARM = 1e-3
#: the lowest DFT bin searched (periods up to a third of the record)
LOWEST_BIN = 3


def chance_band_gain(bins: float, false_alarm: float) -> float:
    """The chi-square gain u that the largest of a continuous frequency search over a band
    of ``bins`` DFT bins (two degrees of freedom per frequency) exceeds by chance with
    probability ``false_alarm``: Baluev (2008, MNRAS 385, 1279) for even sampling,
    P(max > u) = (1 + bins sqrt(pi/3) sqrt(u/2)) exp(-u/2) (the 1: a single frequency's
    chi-square law, what a band of few bins tends to), solved by fixed point."""
    u = 2.0 * math.log((1.0 + bins) / false_alarm)
    for _ in range(30):
        u = 2.0 * math.log((1.0 + bins * math.sqrt(math.pi / 3.0) * math.sqrt(u / 2.0)) / false_alarm)
    return u


def octave_bands(n: int) -> list[tuple[int, int]]:
    """The periodic search's bands: octaves of DFT bins [LOWEST_BIN 2^j, LOWEST_BIN
    2^(j+1)) up to the last bin below Nyquist, as (first, end)."""
    top = (n + 1) // 2  # not the Nyquist bin of an even n (one real degree of freedom)
    out, lo = [], LOWEST_BIN
    while lo < top:
        out.append((lo, min(2 * lo, top)))
        lo *= 2
    return out


def octave_bars(n: int, false_alarm: float) -> list[float]:
    """Each octave band's (``octave_bands``) chance bar: ``false_alarm`` shared equally
    among the octaves (a weighted Bonferroni: the whole search's false-alarm rate is at
    most ``false_alarm`` by Baluev's law), each searched over its own bins
    (:func:`chance_band_gain`)."""
    bands = octave_bands(n)
    return [chance_band_gain(hi - lo, false_alarm / len(bands)) for lo, hi in bands]


def strongest_line(P: np.ndarray, n: int, false_alarm: float) -> tuple[int, float]:
    """The bin of the PSD-weighted periodogram ``P`` (|Y|^2 / (n S), half a sinusoid's
    chi-square gain at a bin) whose gain 2 P lies furthest above its octave's chance bar
    (``octave_bars``), and that bar."""
    best, bar, excess = LOWEST_BIN, math.inf, -math.inf
    for (lo, hi), u in zip(octave_bands(n), octave_bars(n, false_alarm), strict=True):
        k = lo + int(np.argmax(P[lo:hi]))
        if 2.0 * float(P[k]) - u > excess:
            best, bar, excess = k, u, 2.0 * float(P[k]) - u
    return best, bar


def periodic(ctx: Context) -> Candidate | None:
    """The line of the PSD-weighted periodogram (periods 2 samples .. duration / 3)
    furthest above its octave's chance bar (``strongest_line``: the search's false-alarm
    rate SEARCH_FALSE_ALARM shared among the octaves, so a slow line needs far less gain
    than one among the record's many fast frequencies), frequency refined within a bin of
    it to the maximum of the GLS chi-square of a sinusoid (:func:`line_gain`: on a grid
    of LINE_STEPS_PER_BIN points per bin, then golden section), then fitted by the
    calibrated GLS; its bar is that octave's chance bar, BIC's 3 ln n not on top
    (``Candidate.search_calibrated``: the search's own law sets its false-alarm rate)."""
    n = ctx.n
    if n < 4 * LOWEST_BIN:
        return None
    P = np.abs(ctx.Yf) ** 2 / (n * ctx.wh.S)
    k, search_bar = strongest_line(P, n, SEARCH_FALSE_ALARM)
    peak_power = float(P[k])
    del P  # record-length arrays are let go once used (memory)
    t = ctx.t_s

    def g(nu):
        return line_gain(ctx.wh.w, ctx.Yf, n, np.atleast_1d(nu))

    grid = k + (np.arange(-LINE_STEPS_PER_BIN, LINE_STEPS_PER_BIN + 1)) / LINE_STEPS_PER_BIN
    i = int(np.argmax(g(grid)))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    r = (math.sqrt(5) - 1) / 2
    c, d = b - r * (b - a), a + r * (b - a)
    gc, gd = float(g(c)[0]), float(g(d)[0])
    for _ in range(12):
        if gc > gd:
            b, d, gd = d, c, gc
            c = b - r * (b - a)
            gc = float(g(c)[0])
        else:
            a, c, gc = c, d, gd
            d = a + r * (b - a)
            gd = float(g(d)[0])
    nu = c if gc > gd else d
    f = nu * ctx.sample_rate_hz / n
    tr = t - t[0]
    X = np.column_stack((np.sin(2 * np.pi * f * tr), np.cos(2 * np.pi * f * tr)))
    Xf = ctx.wh.fft(X)
    fit, wh = judged_whittle(ctx, X, Xf)
    sa, ca = fit.beta
    # the errors with the frequency free: the fit linearised in f, the sinusoid's derivative
    # (deg/h per Hz) a third column (Gauss-Newton: the Fisher information with all three
    # free), under the PSD the line was judged against
    Xf3 = np.column_stack((Xf, wh.fft(2 * np.pi * tr * (sa * X[:, 1] - ca * X[:, 0]))))
    del tr
    fit3 = wh.gls(Xf3, ctx.Yf)
    cov = (fit3 if exact_law(ctx) is None else exact_cov_fit(ctx, fit3, wh, Xf3)).cov
    amp = math.hypot(sa, ca)
    # A sin(2 pi f (t - t0) + ph0) = A sin(2 pi f t + phase) with phase = ph0 - 2 pi f t0
    phase = math.remainder(math.atan2(ca, sa) - 2 * np.pi * f * t[0], 2 * np.pi)
    period = 1.0 / f
    amp_ = max(amp, 1e-300)
    se_f, se_amp, se_phase = (_delta_se(cov, g) for g in (
        (0.0, 0.0, 1.0), (sa / amp_, ca / amp_, 0.0), (-ca / amp_ ** 2, sa / amp_ ** 2, -2 * np.pi * t[0])))
    params = {"period_s": period, "amplitude_dph": amp, "phase_rad": phase}
    ev = (f"periodogram line at {period:.6g} s (PSD-weighted power {peak_power:.3g}x the noise), "
          f"amplitude {estimate_text(amp, se_amp)} deg/h")
    return Candidate("periodic", params, {"period_s": se_f / f ** 2, "amplitude_dph": se_amp, "phase_rad": se_phase},
                     fit.chi2_gain, 3, ev, X @ fit.beta, X, search_bar=search_bar, search_calibrated=True)


def _delta_se(cov: np.ndarray, grad: tuple[float, ...]) -> float:
    """Standard error of a function of the coefficients whose covariance is ``cov``, by its
    gradient ``grad`` (delta method); NaN where that is not a positive number."""
    g = np.asarray(grad)
    v = float(g @ cov @ g)
    return math.sqrt(v) if np.isfinite(v) and v > 0 else float("nan")


#: the frequency of a periodic term is searched on this many points per DFT bin (then golden section)
LINE_STEPS_PER_BIN = 16
#: a sinusoid's DFT is taken over this many bins either side of its frequency (and of its mirror image)
LINE_KERNEL_BINS = 512


def line_gain(w: np.ndarray, Yf: np.ndarray, n: int, nus: np.ndarray) -> np.ndarray:
    """Whittle GLS chi-square gain of a sinusoid (sin and cos columns) at each continuous
    frequency of ``nus`` (in DFT bins) for the residual's rfft ``Yf`` with the GLS weights
    ``w`` (``Whittle.w``): the design's DFT in closed form, sum_t e^(2 pi i x t / n) =
    (1 - e^(2 pi i x)) / (1 - e^(2 pi i x / n)) at x = +-nu - j, over the bins within
    LINE_KERNEL_BINS of the line (the rest holds about 2 / (pi^2 LINE_KERNEL_BINS) of its
    weight, 0.04 %), so each frequency costs O(LINE_KERNEL_BINS), not an FFT of the
    record. Gaps are not in that design (the exact fit of the chosen frequency has them)."""
    out = np.empty(len(nus))
    nb = len(Yf)
    for q, nu in enumerate(nus):
        lo = max(1, int(nu) - LINE_KERNEL_BINS)
        j = np.arange(lo, min(nb, int(nu) + LINE_KERNEL_BINS + 1))
        d_plus, d_minus = _dirichlet(nu - j, n), _dirichlet(-nu - j, n)
        X = np.column_stack(((d_plus - d_minus) / 2j, (d_plus + d_minus) / 2.0))
        A, bb = weighted_products(w[j], X, Yf[j])
        try:
            out[q] = float(bb @ np.linalg.solve(A, bb))
        except np.linalg.LinAlgError:
            out[q] = 0.0
    return out


def _dirichlet(x: np.ndarray, n: int) -> np.ndarray:
    """sum over t < n of e^(2 pi i x t / n) = e^(i pi x (n - 1) / n) n sinc(x) / sinc(x / n)
    (n at x = 0)."""
    return np.exp(1j * np.pi * x * (n - 1) / n) * (n * np.sinc(x) / np.sinc(x / n))


def chance_step_gain(positions: int, false_alarm: float) -> float:
    """The chi-square gain u that the largest of a change-point scan over ``positions``
    step times exceeds by chance with probability at most ``false_alarm`` (Bonferroni:
    positions x P(chi-square 1 dof > u) = false_alarm). BIC's 2 ln n is that bar only when
    the scan's statistics at neighbouring times are nearly the same (white noise); under
    the model's coloured noise the GLS whitens a step towards a one-sample impulse, its
    statistics at neighbouring times decorrelate, and the scan's maximum beats 2 ln n far
    more often (1 Hz, 9 h records of N 0.05, B 0.2: 15 of 200 replicates; of N alone: 0)."""
    return float(chi2.isf(false_alarm / max(positions, 1), 1))


def bias_step(ctx: Context) -> Candidate | None:
    """Best single bias step over 1 %..99 % of the record (exact GLS scan); its bar is at
    least :func:`chance_step_gain` over the positions scanned at SEARCH_FALSE_ALARM."""
    n = ctx.n
    lo, hi = int(0.01 * n), int(0.99 * n)
    n0, step, gain = detectors.step_scan(ctx.wh, ctx.Yf, lo, hi)
    X = (np.arange(n) >= n0).astype(float)[:, None]
    fit = judged_gls(ctx, X)
    t_step = float(ctx.t_s[n0] - 0.5 / ctx.sample_rate_hz)
    params = {"t_s": t_step, "step_dph": float(fit.beta[0])}
    ev = f"change-point scan: bias step of {estimate_text(fit.beta[0], fit.se[0])} deg/h at t = {t_step:.6g} s"
    return Candidate("bias_step", params, {"step_dph": float(fit.se[0])}, fit.chi2_gain, 2, ev,
                     X @ fit.beta, X, search_bar=chance_step_gain(hi - lo, SEARCH_FALSE_ALARM))


def _scan_1d(ctx: Context, make: Callable[[float, np.ndarray], np.ndarray], grid: np.ndarray, refine: int = 8,
             slow: Callable[[float], bool] = lambda v: True):
    """Best value of a nonlinear parameter on ``grid`` then on a finer grid around it, by
    the GLS gain of the design ``make(v, t)`` (at times t, s): on the record's block
    means (``coarse``) for the values ``slow`` says vary slowly over a block (the final
    fit is the caller's, on every sample)."""
    co = coarse(ctx)

    def gain(v):
        if co is not None and slow(v):
            return co.gain(make(v, co.t))
        return ctx.wh.gls(ctx.wh.fft(make(v, ctx.t_s)), ctx.Yf).chi2_gain

    gains = [gain(v) for v in grid]
    i = int(np.argmax(gains))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    fine = np.linspace(lo, hi, refine + 2)[1:-1]
    g2 = [gain(v) for v in fine]
    j = int(np.argmax(g2))
    return (fine[j], g2[j]) if g2[j] > gains[i] else (grid[i], gains[i])


def coarse(ctx: Context) -> Coarse | None:
    """The GLS on the context's block means (fitting.Coarse, blocks of
    fitting.coarse_block samples; computed once per context), or None for a record too
    short to need it."""
    if "coarse" not in ctx.cache:
        b = coarse_block(ctx.n)
        ctx.cache["coarse"] = None if b < 2 else Coarse(ctx.wh.S, ctx.y, ctx.wh.valid, ctx.t_s, b)
    return ctx.cache["coarse"]


def rate_ramp(ctx: Context) -> Candidate | None:
    """Linear rate drift starting at t0 (scanned over 0..90 % of the record)."""
    t = ctx.t_s
    T = t[-1] - t[0]

    def make(t0, tt):
        return (np.maximum(tt - t0, 0.0) / 3600.0)[:, None]

    t0, _ = _scan_1d(ctx, make, t[0] + T * np.linspace(0.0, 0.9, 16))
    X = make(t0, t)
    fit = judged_gls(ctx, X)
    params = {"slope_dphh": float(fit.beta[0]), "t0_s": float(t0)}
    ev = f"trend regression: rate slope {estimate_text(fit.beta[0], fit.se[0])} deg/h^2 from t = {t0:.6g} s"
    return Candidate("rate_ramp", params, {"slope_dphh": float(fit.se[0])}, fit.chi2_gain, 2, ev, X @ fit.beta, X)


def warm_up(ctx: Context) -> Candidate | None:
    """Exponential settling from the start of the record, time constant scanned on a
    log grid from max(10 samples, 3 matched-filter lengths) to half the record."""
    t = ctx.t_s
    T = t[-1] - t[0]
    t0 = float(t[0])

    def make(ltau, tt):
        return np.exp(-(tt - t0) / math.exp(ltau))[:, None]

    # faster than a few matched-filter lengths it cannot be told from the record's ends
    # (the circular GLS joins them) or from a glitch
    tau_lo = max(10.0, 3.0 * detectors.kernel_length(ctx.wh)) / ctx.sample_rate_hz
    b = coarse_block(ctx.n)  # a settling over 4 blocks or more is scanned on block means
    ltau, _ = _scan_1d(ctx, make, np.linspace(math.log(tau_lo), math.log(T / 2), 14),
                       slow=lambda lt: math.exp(lt) * ctx.sample_rate_hz >= 4 * b)
    X = make(ltau, t)
    fit = judged_gls(ctx, X)
    tau = math.exp(ltau)
    params = {"amplitude_dph": float(fit.beta[0]), "tau_s": tau, "t0_s": t0}
    ev = f"settling fit: A = {estimate_text(fit.beta[0], fit.se[0])} deg/h, tau = {tau:.4g} s from t = {t0:.6g} s"
    return Candidate("warm_up", params, {"amplitude_dph": float(fit.se[0])}, fit.chi2_gain, 2, ev, X @ fit.beta, X)


def scale_factor(ctx: Context) -> Candidate | None:
    """Scale-factor error on rot_dps: symmetric, and with asymmetry (better BIC wins)."""
    rot = ctx.aux.get("rot_dps")
    if rot is None or not varies(rot):
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
    fit = judged_gls(ctx, X)
    params = {"ppm": 0.0, "asym_ppm": 0.0}
    se = {}
    for i, nm in enumerate(names):
        params[nm] = float(fit.beta[i])
        se[nm] = float(fit.se[i])
    ev = ("regression on 3600 rot_dps: " + ", ".join(f"{nm} {estimate_text(params[nm], se[nm])}" for nm in names)
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
    if temp is None or not varies(temp):
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
    fit = judged_gls(ctx, X, np.column_stack([fcols[nm] for nm in names]))
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
          + ", ".join(f"{nm} {estimate_text(v[nm], s[nm])}" for nm in names)
          + f"; predicted drift {pp:.3g} deg/h peak-to-peak over a {np.nanmax(temp) - np.nanmin(temp):.3g} degC span")
    extra = 0 if (smooth_s, diff_s) == THERMAL_SMOOTHING[0] else 1  # a smoothing moved from the default is fitted
    return Candidate("thermal_drift", params, se, fit.chi2_gain, len(names) + extra, ev, rate + c0, X)

