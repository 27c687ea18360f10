"""``aux_response``: a law outside the catalogue that follows the measured conditions
(docs/explain.md, "Laws outside the catalogue"): a sparse sum of terms, coefficient x
feature, over every aux column and every other axis's rate column (the feature grammar
of fogmon.sim.features), selected by forward stepwise regression on the residual.

- **Noise.** Every fit is the Whittle GLS of the mean-type kinds (the model PSD
  calibrated to the residual, ``Context.wh``), judged like theirs against the noise its
  own residual shows at the slowest frequencies (fitting.low_band_flicker): a flicker
  excess there joins the PSD and the terms are selected again under it.
- **The search.** Each step adds the feature with the largest chi-square gain; it enters
  only above its bar, the higher of BIC's ln n and the gain that the largest of the m
  features still searched exceeds by chance with probability SEARCH_FALSE_ALARM
  (chi-square, one degree of freedom, Bonferroni over m). The candidate's BIC bar is the
  sum of its terms' bars (``search_bar``): k counts the search.
- **Colinear features.** A feature whose whitened correlation with the one chosen
  (given the terms already in) exceeds COLINEAR_CORR and whose gain is within
  INDISTINCT_CHI2 of it is named with the term ("vib_g and vib_g^2 are colinear here;
  the data cannot tell them apart") and never enters as a term of its own, so a term is
  not split arbitrarily between them.
- **Left to the catalogue.** Features a catalogue kind already fits on its channel
  (CATALOGUE_FEATURES: rot_dps and abs(rot_dps) are ``scale_factor``'s, temp_c, temp_c^2
  and d(temp_c)/dt ``thermal_drift``'s) are not searched.

Each coefficient has its 95 % interval (1.96 standard errors of the GLS) and a physics
name from fogmon.explain.physics. The fitted law is offset to average 0 over the record
(``offset_dph``), so the bias stays the record's mean.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from fogmon.explain.candidates.base import Candidate, Context, exact_cov_fit, exact_law
from fogmon.explain.candidates.mean import SEARCH_FALSE_ALARM
from fogmon.explain.fitting import MIN_BAND_BINS, low_band_flicker
from fogmon.explain.physics import physics_of
from fogmon.sim.effects import feature_values
from fogmon.sim.features import Feature, coef_unit

#: features a catalogue kind already fits on its channel (its law, parameters and units)
CATALOGUE_FEATURES = frozenset({"rot_dps", "abs(rot_dps)", "temp_c", "temp_c^2", "d(temp_c)/dt"})
#: most features searched: every channel's own (linear, square, abs when it changes
#: sign, d/dt) first, then products of two channels in column order
MAX_FEATURES = 64
#: most terms one law holds
MAX_TERMS = 6
#: |correlation| of two whitened features (given the terms in) above which they are colinear
COLINEAR_CORR = 0.95
#: chi-square gains closer than this (2 ln 20, "strong" evidence) cannot tell two colinear features apart
INDISTINCT_CHI2 = 6.0
#: whitened |correlation| above which a feature duplicates an earlier one (pumps^2 = pumps)
DUPLICATE_CORR = 1.0 - 1e-9
#: smoothing (s) and difference step (s) of d(NAME)/dt (the effect's defaults)
SMOOTH_S, DIFF_STEP_S = 10.0, 1.0
#: 95 % two-sided normal quantile of the coefficients' intervals
Z95 = 1.959963984540054


@dataclass
class _Library:
    """The features searched on a record: their texts, the rfft of each centred and
    scaled to unit rms over the valid samples (real and imaginary parts, bins x
    features) and that scale."""

    features: list[Feature]
    Xr: np.ndarray
    Xi: np.ndarray
    scale: np.ndarray
    channels: list[str]


@dataclass
class _Step:
    """One accepted step of the search: feature index ``j``, its chi-square ``gain``, its
    ``bar`` and the colinear features the data cannot tell from it (index, |corr|)."""

    j: int
    gain: float
    bar: float
    colinear: list[tuple[int, float]] = field(default_factory=list)


_cache: dict = {}


def _library(ctx: Context) -> _Library | None:
    """The record's features (cached for the record: the aux channels and valid mask do
    not change between selection rounds), or None when no channel varies."""
    key = (id(ctx.aux), id(ctx.valid), ctx.n)
    if _cache.get("key") == key:
        return _cache["lib"]
    v = ctx.valid
    chans = [k for k, a in ctx.aux.items() if np.all(np.isfinite(a[v])) and np.ptp(a[v]) > 0]
    singles, products = [], []
    for i, c in enumerate(chans):
        a = ctx.aux[c][v]
        shapes = ("linear", "square", "abs", "rate") if a.min() < 0 < a.max() else ("linear", "square", "rate")
        singles += [Feature(s, (c,)) for s in shapes]
        products += [Feature("product", (c, d)) for d in chans[i + 1:]]
    feats = [f for f in singles + products if f.text not in CATALOGUE_FEATURES][:MAX_FEATURES]
    kept, cols, scale = [], [], []
    for f in feats:
        x = feature_values(f, ctx.t_s, ctx.aux, SMOOTH_S, DIFF_STEP_S)
        x = np.where(v, x - x[v].mean(), 0.0)
        s = float(np.sqrt(np.mean(x[v] ** 2)))
        if s > 0 and math.isfinite(s):
            kept.append(f)
            cols.append(np.fft.rfft(x / s))
            scale.append(s)
    if not kept:
        return None
    X = np.column_stack(cols)
    lib = _Library(kept, np.ascontiguousarray(X.real), np.ascontiguousarray(X.imag), np.array(scale), chans)
    _cache.clear()
    _cache.update(key=key, lib=lib, refs=(ctx.aux, ctx.valid))
    return lib


def _gram(lib: _Library, w: np.ndarray, Yf: np.ndarray, rows: slice = slice(None),
          block: int = 1 << 15) -> tuple[np.ndarray, np.ndarray]:
    """A = Re(X^H W X) and b = Re(X^H W Y) over the bins ``rows`` (weights ``w``)."""
    Xr, Xi, w, Yr, Yi = lib.Xr[rows], lib.Xi[rows], w[rows], Yf.real[rows], Yf.imag[rows]
    F = Xr.shape[1]
    A, b = np.zeros((F, F)), np.zeros(F)
    for lo in range(0, len(w), block):
        s = slice(lo, lo + block)
        ww = w[s][:, None]
        Wr, Wi = Xr[s] * ww, Xi[s] * ww
        A += Wr.T @ Xr[s] + Wi.T @ Xi[s]
        b += Wr.T @ Yr[s] + Wi.T @ Yi[s]
    return A, b


def _distinct(A: np.ndarray) -> np.ndarray:
    """Indices of the features that do not duplicate an earlier one (whitened |corr|
    above DUPLICATE_CORR)."""
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    C = np.abs(A / d[:, None] / d[None, :])
    keep: list[int] = []
    for j in range(len(d)):
        if d[j] > 1e-150 and not any(C[j, k] > DUPLICATE_CORR for k in keep):
            keep.append(j)
    return np.array(keep, dtype=int)


def _forward(A: np.ndarray, b: np.ndarray, penalty: float) -> list[_Step]:
    """Forward stepwise selection on the Gram matrix ``A`` and ``b`` (module docstring):
    each step's gain r^2 / d by the Schur complement of the terms in."""
    F = len(b)
    diag = np.diag(A).copy()
    sel: list[int] = []
    steps: list[_Step] = []
    blocked = np.zeros(F, dtype=bool)
    while len(sel) < MAX_TERMS:
        if sel:
            AS = A[:, sel]
            M = np.linalg.inv(A[np.ix_(sel, sel)])
            r = b - AS @ (M @ b[sel])
            d = diag - np.einsum("ij,jk,ik->i", AS, M, AS)
        else:
            AS, M, r, d = np.zeros((F, 0)), np.zeros((0, 0)), b.copy(), diag.copy()
        ok = ~blocked & (d > 1e-9 * diag)
        ok[sel] = False
        if not ok.any():
            break
        gain = np.where(ok, r * r / np.where(ok, d, 1.0), -np.inf)
        j = int(np.argmax(gain))
        bar = max(penalty, float(chi2.isf(SEARCH_FALSE_ALARM / int(ok.sum()), 1)))
        if not gain[j] > bar:
            if not steps:
                steps.append(_Step(j, float(gain[j]), bar))  # the best, below its bar
            break
        cov = A[:, j] - AS @ (M @ A[sel, j])
        corr = np.abs(cov) / np.sqrt(np.maximum(d * d[j], 1e-300))
        col = [(int(k), float(corr[k])) for k in np.flatnonzero(ok & (corr > COLINEAR_CORR))
               if k != j and gain[k] >= gain[j] - INDISTINCT_CHI2]
        blocked[[k for k, _ in col]] = True
        sel.append(j)
        steps.append(_Step(j, float(gain[j]), bar, col))
    return steps


def _select(ctx: Context, lib: _Library) -> tuple[list[_Step], np.ndarray, np.ndarray, bool]:
    """The search under the calibrated PSD, then again under the PSD with the flicker
    excess its residual shows at the slowest frequencies (when significant): the steps,
    the Gram matrix and b they were taken on, and whether that excess joined."""
    wh, n = ctx.wh, ctx.n
    A, b = _gram(lib, wh.w, ctx.Yf)
    keep = _distinct(A)
    A, b = A[np.ix_(keep, keep)], b[keep]
    steps = _forward(A, b, ctx.penalty)
    sel = [s.j for s in steps if s.gain > s.bar]
    R = ctx.Yf.copy()
    if sel:
        beta = np.linalg.solve(A[np.ix_(sel, sel)], b[sel])
        R = R - (lib.Xr[:, keep[sel]] + 1j * lib.Xi[:, keep[sel]]) @ beta
    S2 = low_band_flicker(wh.S, R, n)
    flicker = S2 is not wh.S
    if flicker:
        low = slice(1, MIN_BAND_BINS)
        dw = np.zeros(len(wh.w))
        dw[low] = 2.0 / (n * S2[low]) - wh.w[low]
        dA, db = _gram(lib, dw, ctx.Yf, low)
        A, b = A + dA[np.ix_(keep, keep)], b + db[keep]
        steps = _forward(A, b, ctx.penalty)
    for s in steps:  # indices into the library
        s.j = int(keep[s.j])
        s.colinear = [(int(keep[k]), c) for k, c in s.colinear]
    full = np.zeros((len(lib.features),) * 2)
    full[np.ix_(keep, keep)] = A
    fb = np.zeros(len(lib.features))
    fb[keep] = b
    return steps, full, fb, flicker


def aux_response(ctx: Context) -> Candidate | None:
    """The law of the aux channels and other axes' rates the residual follows (module
    docstring); the best single feature, below its bar, when no term enters."""
    lib = _library(ctx)
    if lib is None:
        return None
    steps, A, b, flicker = _select(ctx, lib)
    terms = [s for s in steps if s.gain > s.bar] or steps[:1]
    sel = [s.j for s in terms]
    cov = np.linalg.inv(A[np.ix_(sel, sel)])
    beta = cov @ b[sel]
    gain = float(b[sel] @ beta)
    coef = beta / lib.scale[sel]
    se = np.sqrt(np.maximum(np.diag(cov), 0.0)) / lib.scale[sel]
    feats = [lib.features[j] for j in sel]
    X = np.column_stack([feature_values(f, ctx.t_s, ctx.aux, SMOOTH_S, DIFF_STEP_S) for f in feats])
    if exact_law(ctx) is not None:  # long memory: the errors of the design's GLS under the model's law
        Xf = ctx.wh.fft(X)
        se = exact_cov_fit(ctx, ctx.wh.gls(Xf, ctx.Yf), ctx.wh, Xf).se
    law = X @ coef
    offset = -float(np.mean(law[ctx.valid]))
    meta = getattr(ctx, "meta", {})
    table = []
    for f, c, s, st in zip(feats, coef.tolist(), se.tolist(), terms, strict=True):
        table.append({"feature": f.text, "coef": c, "coef_lo": c - Z95 * s, "coef_hi": c + Z95 * s,
                      "unit": coef_unit(f, meta), "physics": physics_of(f, meta),
                      "colinear": [lib.features[k].text for k, _ in st.colinear]})
    physics = "; ".join(dict.fromkeys(t["physics"] for t in table if t["physics"]))
    params = {"terms": table, "physics": physics, "smooth_s": SMOOTH_S, "diff_step_s": DIFF_STEP_S,
              "offset_dph": offset}
    return Candidate("aux_response", params, {t["feature"]: float(s) for t, s in zip(table, se, strict=True)},
                     gain, len(sel), _evidence(lib, terms, table, flicker), law + offset, X,
                     search_bar=float(sum(s.bar for s in terms)))


def _evidence(lib: _Library, steps: list[_Step], table: list[dict], flicker: bool) -> str:
    """The search and its terms in words, colinear features named."""
    head = (f"forward stepwise regression of the residual on {len(lib.features)} features of "
            f"{', '.join(lib.channels)} (Whittle GLS with the calibrated noise PSD"
            + (", raised by the residual's own flicker excess at the slowest frequencies" if flicker else "")
            + "): ")
    terms = "; ".join(f"{t['feature']} {t['coef']:.4g} [{t['coef_lo']:.4g}, {t['coef_hi']:.4g}] {t['unit']} "
                      f"(chi2 gain {s.gain:.1f}, bar {s.bar:.1f})" for t, s in zip(table, steps, strict=True))
    col = [f"{' and '.join([t['feature'], *t['colinear']])} are colinear here (|corr| of the whitened features "
           f"{max(c for _, c in s.colinear):.3f}); the data cannot tell them apart"
           for t, s in zip(table, steps, strict=True) if s.colinear]
    return head + terms + ("; " + "; ".join(col) if col else "")
