"""The ``noise`` candidate: the model's own IEEE-952 coefficients (Q, N, B, K) are wrong;
the terms the recording's Allan deviation puts outside their 95 % interval, corrected."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.stats import norm

from fogmon.davar.batch import oadev
from fogmon.davar.fit import IDENTIFY_Z, fit_avar
from fogmon.davar.theory import avar_terms_to_coefficients, coefficients_to_avar_terms
from fogmon.explain.candidates.base import (
    LEAKAGE_FLOOR,
    WHOLE_RECORD_NOTE,
    Candidate,
    Context,
    model_psd_full,
    passband_part,
    periodogram,
    stoch_psd,
    white_rms_dpsh,
)
from fogmon.explain.fitting import BinnedPeriodogram, model_psd, rfft_omega
from fogmon.sim.model import EFFECT_KINDS, Noise, SensorModel

#: two-sided confidence of the intervals of the noise effect (and of "differs")
NOISE_CONFIDENCE = 0.95
#: the coefficients the noise effect may correct (index into theory.POWERS); R is the
#: deterministic part's (a wrong R is a rate_ramp effect)
NOISE_TERMS = ("Q_arcsec", "N_dpsh", "B_dph", "K_dphsh")


#: fixed-point steps refining the corrected terms (the first correction is exact when
#: the terms do not interact in the fit)
NOISE_ITERATIONS = 2


def expected_avar(S: np.ndarray, n: int, m: np.ndarray) -> np.ndarray:
    """Allan variance ((deg/h)^2) at averaging factors ``m`` (2 m <= n / 2) of a process
    with PSD ``S`` at the rfft bins of an n-sample record (the DC bin left out), from
    its circular autocovariance r = irfft(S): (4 V(m) - V(2 m)) / (2 m^2), V(m) = m r_0
    + 2 sum_{k<m} (m - k) r_k the variance of a sum of m samples - the same value as
    sum over the circle of S 2 sin^4(m w / 2) / (m^2 sin^2(w / 2)) / n, in O(n) for
    every m. Only the lags below 2 max(m) are summed (memory: a 1e7-sample record's
    autocovariance is 80 MB; the spectrum is built as the complex array the inverse
    transform reads, not a real one it would copy)."""
    m = np.asarray(m, dtype=np.int64)
    Sf = np.zeros(len(S), dtype=np.complex128)
    np.copyto(Sf.real, S, where=np.isfinite(S))
    Sf[0] = 0.0
    top = 2 * int(m.max()) if m.size else 1  # c0[j] and c1[j] are read for j < 2 m
    r = np.fft.irfft(Sf, n)[:top].copy()
    del Sf
    c0 = np.concatenate(([0.0], np.cumsum(r[1:])))      # c0[j] = sum_{1 <= k <= j} r_k
    c1 = np.concatenate(([0.0], np.cumsum(np.arange(1, len(r), dtype=float) * r[1:])))

    def var_sum(mm: np.ndarray) -> np.ndarray:
        j = mm - 1
        return mm * r[0] + 2.0 * (mm * c0[j] - c1[j])

    return (4.0 * var_sum(m) - var_sum(2 * m)) / (2.0 * m.astype(float) ** 2)


def fit_coefficients(y: np.ndarray, valid: np.ndarray, stoch: SensorModel, sample_rate_hz: float, white_dpsh: float,
                     S: np.ndarray | None = None):
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
    interact in the fit), or None when the ADEV cannot be fitted. ``S``: the model's PSD
    at the record's rfft bins, when the caller has it."""
    n = len(y)
    # alpha=0: the intervals are not used here, and a noise type skips the mixture's fits
    r = oadev(np.where(valid, y, np.nan), sample_rate_hz, "octave", valid=valid, alpha=0)
    a, se, _, up = fit_avar(r.tau_s, r.adev_dph ** 2, r.m, r.n_terms, n, "all")
    S = model_psd(stoch, rfft_omega(n), n, white_dpsh) if S is None else S
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


#: an octave at the top of the band is the sensor's own low-pass when the record's mean
#: periodogram there lies this many standard errors below both the model's PSD and the
#: corrected one (1 / sqrt(periodogram values) each)
ROLLOFF_Z = 4.0


def passband_bins(bp: BinnedPeriodogram, S0: np.ndarray, S1: np.ndarray) -> np.ndarray:
    """The bins of ``bp`` the noise correction is judged on: all but the top octaves
    (down from Nyquist, while each in turn) where the record rolls off below both the
    model's PSD ``S0`` and the corrected ``S1`` by more than ROLLOFF_Z standard errors -
    the sensor's own low-pass (a digital filter), which no IEEE-952 term describes: there
    a white level read from the Allan deviation would be judged against what the filter
    took away (a real MEMS record had its N 2.35 refused for its 10-50 Hz octaves). A
    correction that is merely too large is not below the model's PSD there and is judged
    on every octave."""
    keep = np.ones(len(bp.I), dtype=bool)
    f = bp.omega / (2.0 * np.pi)  # cycles per sample
    hi = 0.5 + 1e-12
    while hi > 4.0 / bp.n:
        band = (f >= hi / 2.0) & (f < hi)
        cnt = float(bp.count[band].sum())
        if cnt < 16:
            break
        lim = 1.0 - ROLLOFF_Z / np.sqrt(cnt)
        r0 = float(np.sum((bp.count * bp.I / S0)[band])) / cnt
        r1 = float(np.sum((bp.count * bp.I / S1)[band])) / cnt
        if not (r0 < lim and r1 < lim):
            break
        keep[band] = False
        hi /= 2.0
    return keep


def noise(ctx: Context) -> Candidate | None:
    """The model's own Q, N, B, K are wrong (fit_coefficients): the terms whose model
    value lies outside the recording's 95 % interval, corrected; scored by the Whittle
    likelihood of the residual's binned periodogram under the model PSD with and without
    the correction (one parameter per corrected term)."""
    wr = white_rms_dpsh(ctx.stoch, ctx)
    fit = fit_coefficients(ctx.y, ctx.valid, ctx.stoch, ctx.sample_rate_hz, wr, model_psd_full(ctx))
    if not fit:
        return None
    bp = passband_part(ctx, periodogram(ctx))  # where the model's filters pass (as the GLS tests)
    new = _corrected(ctx.stoch, fit)
    S0 = stoch_psd(ctx, bp)
    S1 = model_psd(new, bp.omega, ctx.n, white_rms_dpsh(new, ctx))
    floor = LEAKAGE_FLOOR * float(np.median(S0))
    keep = passband_bins(bp, S0, S1)
    gain = bp.deviance(S0, floor, keep) - bp.deviance(S1, floor, keep)
    params = {}
    for k, (v, lo, hi, _) in fit.items():
        params.update({k: v, f"{k}_lo": lo, f"{k}_hi": hi})
    se = {k: (hi - lo) / (2 * 1.959964) for k, (v, lo, hi, _) in fit.items()}

    def heldout():
        # A half whose own fit corrects nothing predicts with the whole record's correction
        # (a wrong coefficient is stationary: what lowers the deviance of one half must
        # lower the other's), judged wherever it lowers its own half's deviance by 9 or
        # more. Before, such a half predicted nothing and was skipped, so a correction that
        # neither half finds on its own passed: a settling at 3000 s of a 7200 s record was
        # named "your B is 0.139 deg/h, not 0.02" (both halves "chi2 drop 0.0 (expected 0.0)"),
        # though the whole record's B raises the second half's deviance. And the whole
        # record's correction must lower the two halves' deviance alike (``_unbalanced``).
        out = []
        h = ctx.n // 2
        halves = (slice(0, h), slice(h, 2 * h))
        bps = [passband_part(ctx, periodogram(ctx, p)) for p in halves]
        s0s = [model_psd(ctx.stoch, bp.omega, h, wr) for bp in bps]
        apart = _unbalanced(ctx, bps, s0s, new)
        for a, b in ((0, 1), (1, 0)):
            fa = fit_coefficients(ctx.y[halves[a]], ctx.valid[halves[a]], ctx.stoch, ctx.sample_rate_hz, wr)
            na = _corrected(ctx.stoch, fa) if fa else new
            gains = []
            for bb, s0 in ((bps[b], s0s[b]), (bps[a], s0s[a])):
                s1 = model_psd(na, bb.omega, h, white_rms_dpsh(na, ctx))
                fl = LEAKAGE_FLOOR * float(np.median(s0))
                kb = passband_bins(bb, s0, s1)
                gains.append(bb.deviance(s0, fl, kb) - bb.deviance(s1, fl, kb))
            note = "; ".join(x for x in ("" if fa else WHOLE_RECORD_NOTE, apart) if x)
            out.append((float(gains[0]), float(gains[1]), note, math.inf if apart else 0.0))
        return out  # (tested on the second half, on the first)

    ev = ("robust IEEE-952 fit of the residual's Allan deviation against the one the model predicts "
          "(95 % intervals): " + "; ".join(noise_text(k, *v) for k, v in fit.items()))
    if not keep.all():
        top = float(bp.omega[~keep].min() / (2.0 * np.pi) * ctx.sample_rate_hz)
        ev += (f"; judged below {top:.3g} Hz: above it the record rolls off below the model and the correction "
               f"alike (the sensor's own low-pass, which no IEEE-952 term describes)")
    return Candidate("noise", params, se, float(gain), len(fit), ev, heldout=heldout,
                     corrected_noise=new.noise)


#: the whole record's correction is refused when the two halves' deviance drops under it
#: differ beyond chance (|z| above this: two-sided 0.001) and by more than BALANCE_FACTOR
STATIONARY_Z = 3.29
BALANCE_FACTOR = 4.0


def _unbalanced(ctx: Context, halves: list[BinnedPeriodogram], psd: list[np.ndarray], new: SensorModel) -> str:
    """A note when the whole record's correction ``new`` lowers the two halves' deviance
    (``halves``: their binned periodograms over the pass band, ``psd`` the current model's
    PSD at their bins) unequally beyond chance,
    "" otherwise. A wrong coefficient is stationary: with the corrected PSD S1 the true
    one, each half's drop sum c (I (1/S0 - 1/S1) - ln r) (r = S1 / S0, c the bin's count)
    has mean sum c (r - 1 - ln r) and variance sum c (r - 1)^2, the same in both halves;
    refused when the drops differ by more than STATIONARY_Z standard deviations of the
    difference and the larger is more than BALANCE_FACTOR times the smaller (at large
    gains a small level difference between the halves is already many standard
    deviations: a stationary wrong N, 0.03 deg/sqrt(h) for 0.02, gave drops 14700 and
    16134, z -4.5). A drift is not stationary: a warm-up of 5 deg/h (tau 300 s) plus 5
    deg/h (tau 3000 s) over 3 h at 10 Hz had been named "your K is 0.547, not 0"."""
    h = ctx.n // 2
    drops, var = [], 0.0
    for bp, s0 in zip(halves, psd, strict=True):
        s1 = model_psd(new, bp.omega, h, white_rms_dpsh(new, ctx))
        fl = LEAKAGE_FLOOR * float(np.median(s0))
        drops.append(bp.deviance(s0, fl) - bp.deviance(s1, fl))
        var += float(np.sum(bp.count * (np.maximum(s1, fl) / np.maximum(s0, fl) - 1.0) ** 2))
    z = (drops[0] - drops[1]) / math.sqrt(var) if var > 0 else 0.0
    lo, hi = sorted(drops)
    if abs(z) > STATIONARY_Z and hi > BALANCE_FACTOR * max(lo, 0.0):
        return (f"the whole record's correction lowers the halves' deviance by {drops[0]:.1f} and {drops[1]:.1f} "
                f"(z {z:+.1f}): not stationary")
    return ""


def effect_summary(kind: str, p: dict, model: dict | None = None) -> str:
    """One phrase with the numbers of an effect: its kind's own summary
    (fogmon.sim.model.EFFECT_KINDS); a ``noise`` effect also names the model's values it
    corrects (``model``: the model's [noise])."""
    if kind == "noise" and model is not None:
        return "wrong noise coefficients: " + "; ".join(
            noise_text(k, p[k], p[f"{k}_lo"], p[f"{k}_hi"], model[k]) for k in NOISE_UNIT if k in p)
    return EFFECT_KINDS[kind].summarize(kind, p) if kind in EFFECT_KINDS else kind
