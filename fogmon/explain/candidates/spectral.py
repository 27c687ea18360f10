"""Spectral noise-type candidates: a Gauss-Markov term (``markov``) and the sensor's own
low-pass (``bandwidth``), each by the Whittle likelihood of the residual's binned
periodogram under the model PSD with and without the term."""
from __future__ import annotations

import math

import numpy as np
from scipy import optimize

from fogmon.explain.candidates.base import (
    LEAKAGE_FLOOR,
    WHOLE_RECORD_NOTE,
    Candidate,
    Context,
    estimate_text,
    passband_gain2,
    passband_part,
    periodogram,
    stoch_psd,
    white_rms_dpsh,
)
from fogmon.explain.fitting import BinnedPeriodogram, filter_gain2, markov_psd, model_psd


def markov(ctx: Context) -> Candidate | None:
    """Gauss-Markov term: Whittle likelihood over a log grid of correlation times
    (5 samples .. duration/20), variance by Newton steps (>= 0). A best fit at the
    longest correlation time is refused (a drift, left to the mean-type effects), and at
    the shortest (a white-noise level change, left to the white-level effects). Under a
    ``bandwidth`` filter the term is filtered like the rest of the rate (sim
    BandwidthFilter) and fitted over the filter's pass band (``passband_part``): a
    correlation time of 5 samples or more puts less than 1/(2 pi 5 x 0.45)^2 = 0.5 % of
    its low-frequency PSD near Nyquist, so the bins left out carry next to nothing on it.
    Its held-out check (``_markov_heldout``): a stationary process, so the term fitted on
    one half of the record must lower the other half's deviance."""
    T = ctx.n / ctx.sample_rate_hz
    grid = np.geomspace(5.0 / ctx.sample_rate_hz, T / 20.0, 36)
    bp = passband_part(ctx, periodogram(ctx))
    S0 = stoch_psd(ctx, bp)
    best = _markov_fit(ctx, bp, S0, grid)
    if best is None:
        return None  # at the grid's ends it is a drift or a white-noise level, not a Gauss-Markov term
    g, tc, v = best
    sigma = math.sqrt(v)
    se_sigma, se_tc = _markov_se(ctx, bp, S0, grid, tc, v)
    G = passband_gain2(ctx.stoch, bp.omega)
    band = ("" if G.min() == 1.0 else
            f" over 0-{bp.omega[-1] * ctx.sample_rate_hz / (2 * math.pi):.4g} Hz (the bandwidth filter's pass band)")
    ev = (f"Whittle fit of the residual spectrum{band}: Gauss-Markov sigma {estimate_text(sigma, se_sigma)} deg/h, "
          f"correlation time {estimate_text(tc, se_tc)} s (ADEV hump {0.618 * sigma:.3g} deg/h near tau = "
          f"{1.89 * tc:.3g} s)")
    return Candidate("markov", {"tau_c_s": float(tc), "sigma_dph": sigma},
                     {"sigma_dph": se_sigma, "tau_c_s": se_tc}, g, 2, ev,
                     heldout=lambda: _markov_heldout(ctx, grid, tc, v))


def _markov_se(ctx: Context, bp: BinnedPeriodogram, S0: np.ndarray, grid: np.ndarray, tc: float,
               v: float) -> tuple[float, float]:
    """Standard errors of a Gauss-Markov term's sigma (deg/h) and correlation time (s): half
    the width of each one's 68.3 % profile-likelihood interval (the Whittle deviance,
    -2 ln L, 1 above its least; the other parameter refitted at every point; an end the
    deviance does not reach within ``grid`` or at sigma 0 is that bound). Sigma and the
    correlation time trade off where few bins lie below the corner frequency, and the
    likelihood in the correlation time is skewed: the curvature in sigma at the fitted
    correlation time, in -ln L units, gave errors 1.3-2.7x too small (docs/explain.md,
    "The markov term's standard errors")."""
    G = passband_gain2(ctx.stoch, bp.omega)
    floor = LEAKAGE_FLOOR * float(np.median(S0))
    u_lo, u_hi = math.log(grid[0]), math.log(grid[-1])

    def shape(u: float) -> np.ndarray:
        return G * markov_psd(bp.omega, ctx.sample_rate_hz, 1.0, math.exp(u))

    def dev_tc(u: float) -> float:       # profiled over the variance
        P = shape(u)
        return bp.deviance(S0 + _newton_variance(bp, S0, P) * P, floor)

    shapes = np.array([shape(math.log(t)) for t in grid])

    def dev_v(w: float) -> float:        # profiled over the correlation time (the grid's log-
        d = bp.deviances(S0 + w * shapes, floor)   # even points, a parabola through the least)
        j = int(np.argmin(d))
        if 0 < j < len(d) - 1:
            vertex = _parabola_vertex(d[j - 1], d[j], d[j + 1])
            if vertex is not None:
                return vertex[1]
        return float(d[j])

    u_ends = [_crossing(dev_tc, math.log(tc), end, 1e-3) for end in (u_lo, u_hi)]
    r = math.sqrt(v)                     # sigma, profiled over the variance v = sigma^2
    s_ends = [_crossing(lambda x: dev_v(x * x), r, end, 1e-3 * r) for end in (0.0, 8.0 * r)]
    return (s_ends[1] - s_ends[0]) / 2.0, (math.exp(u_ends[1]) - math.exp(u_ends[0])) / 2.0


def _crossing(f, x0: float, end: float, xtol: float) -> float:
    """Where the deviance profile ``f`` rises 1 above its value at the estimate ``x0``
    between ``x0`` and ``end`` (to ``xtol``), or ``end`` when it does not. (Each profile
    is read against its own value at the estimate: the two profiles' approximations of
    the least differ by a little, and a real profile can be flat or rough there.)"""
    level = f(x0) + 1.0
    if f(end) <= level:
        return end
    return float(optimize.brentq(lambda x: f(x) - level, x0, end, xtol=xtol))


def _markov_fit(ctx: Context, bp: BinnedPeriodogram, S0: np.ndarray,
                grid: np.ndarray) -> tuple[float, float, float] | None:
    """The best (deviance gain, correlation time (s), variance (deg/h)^2) of a Gauss-Markov
    term over the correlation times ``grid`` on the binned periodogram ``bp`` against the
    noise PSD ``S0``; None when no variance is positive or the best lies at the grid's ends."""
    G = passband_gain2(ctx.stoch, bp.omega)
    floor = LEAKAGE_FLOOR * float(np.median(S0))
    d0 = bp.deviance(S0, floor)

    def fit(tc: float) -> tuple[float, float, float] | None:
        P = G * markov_psd(bp.omega, ctx.sample_rate_hz, 1.0, tc)
        v = _newton_variance(bp, S0, P)
        return (d0 - bp.deviance(S0 + v * P, floor), tc, v) if v > 0 else None

    fits = [fit(tc) for tc in grid]
    best = max((f for f in fits if f is not None), default=None, key=lambda f: f[0])
    if best is None or best[1] >= grid[-1] or best[1] <= grid[0]:
        return None
    # the correlation time between the grid's log-even neighbours (its steps are ~20 %
    # wide: a step's worth of error in tau_c moved sigma by more than its standard error):
    # the vertex of the parabola through the three gains
    i = int(np.searchsorted(grid, best[1]))
    lo, hi = fits[i - 1], fits[i + 1]
    vertex = None if lo is None or hi is None else _parabola_vertex(-lo[0], -best[0], -hi[0])
    if vertex is None:
        return best
    fine = fit(best[1] * (grid[i + 1] / grid[i]) ** vertex[0])
    return fine if fine is not None and fine[0] > best[0] else best


def _parabola_vertex(ym: float, y0: float, yp: float) -> tuple[float, float] | None:
    """The least of the parabola through (-1, ym), (0, y0), (1, yp): its abscissa (in
    steps) and value, or None when the three points are not convex."""
    curv = ym - 2.0 * y0 + yp
    if not curv > 0:
        return None
    return 0.5 * (ym - yp) / curv, float(y0 - (yp - ym) ** 2 / (8.0 * curv))


def _markov_gain(ctx: Context, bp: BinnedPeriodogram, S0: np.ndarray, tc: float, v: float) -> float:
    """The deviance a Gauss-Markov term (correlation time ``tc`` s, variance ``v``) removes
    from the binned periodogram ``bp`` against the noise PSD ``S0``."""
    P = passband_gain2(ctx.stoch, bp.omega) * markov_psd(bp.omega, ctx.sample_rate_hz, 1.0, tc)
    floor = LEAKAGE_FLOOR * float(np.median(S0))
    return float(bp.deviance(S0, floor) - bp.deviance(S0 + v * P, floor))


#: the most deviance (-ln of the Whittle likelihood, ``BinnedPeriodogram.deviance``) a
#: stationary Gauss-Markov term may lose on one half of the record when its two
#: parameters come from the other half instead of that half's own fit: in theory
#: (theta_a - theta_b)' I (theta_a - theta_b) / 2 with theta_a - theta_b ~ N(0, 2 I^-1),
#: chi2(2 dof), 13.82 at its 0.999 quantile; the grid of correlation times adds to it
#: (losses 1.1-7.2, mean 3.5, on both halves of 6 simulated records of tau_c 30 s, against
#: chi2(2)'s mean 2),
#: so twice that
STATIONARY_LOSS = 27.6


def _markov_heldout(ctx: Context, grid: np.ndarray, tc: float, v: float) -> list[tuple]:
    """The held-out check of a Gauss-Markov term, a stationary process: fitted on one half
    of the record (the whole record's correlation-time grid), the term must lower the
    other half's deviance (judged where it lowers its own half's by 9 or more:
    ``selection._heldout``), by no less than that half's own fit less STATIONARY_LOSS. A
    half whose own fit finds nothing (or only a grid end) predicts with the whole
    record's term, and the other half's drop need only be positive. A process whose
    spectrum moves is refused: a frequency sweep (chirp) of 0.5 deg/h from 0.002 to
    0.05 Hz over 2 h in white noise of 1.9 deg/h per sample (10 Hz) had been named a
    Gauss-Markov term of 12 s; each half's fit lowers the other half's deviance by 348
    and 672, where their own fits lower it by 632 and 845. Returns (on the second half,
    on the first), each (drop on the tested half, drop on the fitting half, note, least
    drop that passes)."""
    h = ctx.n // 2
    halves = [passband_part(ctx, periodogram(ctx, part)) for part in (slice(0, h), slice(h, 2 * h))]
    wr = white_rms_dpsh(ctx.stoch, ctx)
    psd = [model_psd(ctx.stoch, bp.omega, h, wr) for bp in halves]
    fits = [_markov_fit(ctx, bp, s0, grid) for bp, s0 in zip(halves, psd, strict=True)]
    out = []
    for a, b in ((0, 1), (1, 0)):
        fit_a, fit_b = fits[a], fits[b]
        if fit_a is None:  # the whole record's term, on both halves
            out.append((_markov_gain(ctx, halves[b], psd[b], tc, v), _markov_gain(ctx, halves[a], psd[a], tc, v),
                        WHOLE_RECORD_NOTE, 0.0))
            continue
        own_a, t_a, v_a = fit_a
        drop = _markov_gain(ctx, halves[b], psd[b], t_a, v_a)
        if fit_b is None:
            out.append((drop, own_a, "the tested half alone finds nothing", 0.0))
        else:
            bar = fit_b[0] - STATIONARY_LOSS
            note = f"needs above {bar:.1f}: that half's own fit {fit_b[0]:.1f} less {STATIONARY_LOSS}"
            out.append((drop, own_a, note, bar))
    return out


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


def bandwidth(ctx: Context) -> Candidate | None:
    """The sensor's own low-pass: Butterworth order 1..4, cutoff on a log grid from
    fs/500 to 0.49 fs, by Whittle likelihood of the residual spectrum."""
    if any(e.kind == "bandwidth" for e in ctx.stoch.effects):
        return None
    bp = periodogram(ctx)
    S0 = stoch_psd(ctx, bp)
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


