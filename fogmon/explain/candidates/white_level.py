"""White-level candidates: ``vibration_noise`` and ``temperature_noise`` change the
white-noise level over time - the per-segment white level (from the Allan variance at
tau0) regressed on the segment mean of vib_g / temp_c."""
from __future__ import annotations

import numpy as np

from fogmon.explain.candidates.base import Candidate, Context, estimate_text, replace_white, varies
from fogmon.explain.fitting import avar1_of_psd, model_psd, rfft_omega


def _segment_levels(ctx: Context, seg: int):
    """Per-segment white level N (deg/sqrt(h)) from the Allan variance at tau0, and
    segment index boundaries."""
    y = np.where(ctx.valid, ctx.y, np.nan)
    d = np.diff(y)
    nseg = (len(d)) // seg
    d = d[: nseg * seg].reshape(nseg, seg)
    n_ok = np.isfinite(d).sum(axis=1)      # a segment without a valid pair (a gap, motion): NaN, silently
    av1 = np.where(n_ok > 0, np.nansum(d ** 2, axis=1) / np.maximum(n_ok, 1), np.nan) / 2.0
    w = rfft_omega(4096)
    stoch_noN = replace_white(ctx.stoch, 0.0)
    c_other = avar1_of_psd(model_psd(stoch_noN, w, ctx.n), 4096)
    c_white = avar1_of_psd(model_psd(replace_white(ctx.stoch, 1.0, drop_other=True), w, ctx.n), 4096)
    lev = np.sqrt(np.maximum(av1 - c_other, 0.0) / c_white)
    return lev, nseg


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
    if a is None or not varies(a) or any(e.kind == kind for e in ctx.stoch.effects):
        return None
    seg = max(16, ctx.n // 2000)
    lev, nseg = _segment_levels(ctx, seg)
    if nseg < 20:
        return None
    x = np.nanmean(a[: nseg * seg].reshape(nseg, seg), axis=1)
    if not varies(x):  # held over the record (but for gaps or its last samples): nothing to regress on
        return None
    beta, se, s2 = _ols(x, lev)
    tstat = beta[1] / se[1] if se[1] > 0 else 0.0
    N0 = ctx.stoch.noise.N_dpsh
    if kind == "vibration_noise":
        if beta[1] <= 0:
            return None
        params = {"n_gain_dpsh_per_g": float(beta[1])}
        sep = {"n_gain_dpsh_per_g": float(se[1])}
        what = f"N = {beta[0]:.4g} + {estimate_text(beta[1], se[1])} * vib_g deg/sqrt(h)"
    else:
        t_ref = (N0 - beta[0]) / beta[1] if beta[1] != 0 else float(np.nanmean(a))
        params = {"n_gain_dpsh_per_c": float(beta[1]), "t_ref_c": float(t_ref)}
        sep = {"n_gain_dpsh_per_c": float(se[1])}
        what = f"N = {beta[0]:.4g} + {estimate_text(beta[1], se[1])} * temp_c deg/sqrt(h)"

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
