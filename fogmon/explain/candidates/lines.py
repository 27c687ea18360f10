"""The ``vibration_lines`` candidate: narrowband random vibration, lines proposed on the
residual whitened by the model PSD, fitted (centre, bandwidth, rms) by the Whittle
likelihood, with the model's white-equivalent level refitted under them."""
from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from fogmon.explain import detectors
from fogmon.explain.baseline import low_pass_index
from fogmon.explain.candidates.base import (
    LEAKAGE_FLOOR,
    Candidate,
    Context,
    in_passband,
    model_psd_full,
    periodogram,
    replace_white,
    white_rms_dpsh,
)
from fogmon.explain.fitting import BinnedPeriodogram, lines_psd, model_psd, rfft_omega
from fogmon.sim.model import EFFECT_KINDS, Effect, Noise, SensorModel
from fogmon.sim.noise import line_psd

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
#: a whitened-periodogram peak this many times the band median proposes a line
LINE_MIN_RATIO = 4.0
#: the noise levels refitted under vibration lines when the model holds a bandwidth
#: filter (filtered_levels): IEEE-952 name, unit
FILTERED_LEVELS = (("N_dpsh", "deg/sqrt(h)"), ("Q_arcsec", "arcsec"))
#: a refitted noise level is at most this many times its previous value
LEVEL_MAX_RATIO = 2.0


def _whitened(ctx: Context) -> np.ndarray:
    """The residual divided by the model PSD in the frequency domain (white where the
    model fits, a peak where a line is missing; not the calibrated PSD, whose octave
    bands would absorb part of a broad line)."""
    S = model_psd_full(ctx)
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

    def unpack(x):  # the exponents bounded: the simplex may wander far (OverflowError on gring_quiet_bjz)
        f = float(x[0])
        bw = float(min(max(math.exp(min(x[1], math.log(nyq))), bw_lo), f / LINE_MIN_Q))  # narrowband: Q = f / bw
        return f, math.sqrt(math.exp(min(x[2], 700.0))), bw

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
        return (model_psd(replace_white(st, 0.0), omega, n),
                model_psd(replace_white(st, 1.0, drop_other=True), omega, n), st.noise.N_dpsh)
    one = with_white_level(st, 1.0)
    unit = SensorModel(st.sample_rate_hz, 0.0, Noise(0.0, 0.0, 0.0, 0.0, 0.0),
                       [e for j, e in enumerate(one.effects) if j == i or e.kind == "bandwidth"])
    return (model_psd(with_white_level(st, 0.0), omega, n), model_psd(unit, omega, n),
            float(st.effects[i].params["sigma_dph"]))


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
    bps = [periodogram(ctx, sl) for sl in halves]
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
    bp = periodogram(ctx)
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
