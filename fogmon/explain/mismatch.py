"""Where a recording and a model disagree, with honest statistics (docs/explain.md, steps 1-3).

The recording's dynamic Allan variance (DAVAR) on a (window, tau) grid is compared
cell by cell with a parametric bootstrap of the model: B simulated records (same
length, gaps and aux schedule) give, per cell, the mean Allan variance, and, per tau,
the spread of u = (sigma^2 / mean)^(1/3) pooled over windows (Wilson-Hilferty: a scaled
chi-square is close to normal on this scale even at 3-5 degrees of freedom, and the
spread depends on the degrees of freedom, not on the level, so pooling stays right when
the level varies in time).

    z(t, tau) = (u_rec - mean u) / (sd sqrt(1 + 1/B))

The family-wise threshold comes from the bootstrap distribution of max |z| over the
whole grid (each replicate scored leave-one-out, exactly like the recording), with a
Gumbel law fitted to those B maxima so that a 1 % threshold does not need thousands
of replicates. Flagged cells are grouped into connected regions (same sign) with
scipy.ndimage.label. The same is done for the whole-record ADEV (one row, all taus):
a mismatch found there spans the whole time axis.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import ndimage

from fogmon.davar import kernels
from fogmon.davar.batch import reference_level
from fogmon.davar.taus import tau_grid
from fogmon.errors import FogmonError

EULER_GAMMA = 0.5772156649015329
#: the Gumbel law's skewness 12 sqrt(6) zeta(3) / pi^3 and kurtosis (excess 12/5)
GUMBEL_SKEW = 1.1395470994046486
GUMBEL_KURTOSIS = 5.4


@dataclass(frozen=True)
class Grid:
    """The (window, tau) grid: window and hop in samples, window start indices,
    averaging factors m of the map (``m``) and of the whole-record ADEV (``m_whole``)."""

    sample_rate_hz: float
    n: int
    window_n: int
    hop_n: int
    starts: np.ndarray
    m: np.ndarray
    m_whole: np.ndarray
    t0_s: float = 0.0

    @property
    def tau_s(self) -> np.ndarray:
        return self.m / self.sample_rate_hz

    @property
    def tau_whole_s(self) -> np.ndarray:
        return self.m_whole / self.sample_rate_hz

    @property
    def window_s(self) -> float:
        return self.window_n / self.sample_rate_hz

    @property
    def t_centre_s(self) -> np.ndarray:
        return self.t0_s + (self.starts + (self.window_n - 1) / 2.0) / self.sample_rate_hz


def make_grid(n: int, sample_rate_hz: float, window_s: float | None = None, hop_fraction: float = 0.25,
              t0_s: float = 0.0, name: str = "recording") -> Grid:
    """Map grid for an n-sample record: default window = duration / 8 (at least 64 samples),
    hop = window / 4, octave taus up to window / 4; whole-record taus up to n / 4.
    A window longer than half the record is a FogmonError."""
    w = max(64, n // 8) if window_s is None else int(round(window_s * sample_rate_hz))
    if w < 16:
        raise FogmonError(f"`window_s` {window_s:g} s is shorter than 16 samples at {sample_rate_hz:g} Hz")
    if 2 * w > n:
        raise FogmonError(
            f"{name}: {n / sample_rate_hz:g} s ({n} samples) is too short for the {w / sample_rate_hz:g} s map "
            f"window: need at least two windows ({2 * w / sample_rate_hz:g} s)"
        )
    hop = max(1, int(round(w * hop_fraction)))
    starts = np.arange(0, n - w + 1, hop, dtype=np.int64)
    return Grid(
        sample_rate_hz,
        n,
        w,
        hop,
        starts,
        tau_grid(sample_rate_hz, w, "octave"),
        tau_grid(sample_rate_hz, n, "octave"),
        t0_s,
    )


def log_avar(y: np.ndarray, valid: np.ndarray, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """ln Allan variance ((deg/h)^2) of the map cells (T x M) and of the whole record (M'),
    NaN where a cell has no valid term, +inf where it holds a sample above 1e8 deg/h
    (kernels.CEILING_DPH; no other cell is touched by it). Uses the DAVAR engine's
    compensated kernels and reference level."""
    y = np.ascontiguousarray(y, dtype=np.float64)
    ok = valid & np.isfinite(y)
    hi, lo, bad = kernels.prefix_sums_dd(y, ok, reference_level(y, ok))
    s, c = kernels.window_sums(hi, lo, bad, grid.m, grid.starts, grid.window_n)
    sw, cw = kernels.window_sums(hi, lo, bad, grid.m_whole, np.zeros(1, np.int64), grid.n)
    with np.errstate(divide="ignore", invalid="ignore"):
        cell = np.where(c > 0, np.log(np.maximum(s, 1e-300) / (2.0 * c)), np.nan)
        whole = np.where(cw[0] > 0, np.log(np.maximum(sw[0], 1e-300) / (2.0 * cw[0])), np.nan)
    return cell, whole


@dataclass(frozen=True)
class Gumbel:
    """Gumbel law of a maximum statistic (location, scale), fitted by moments to ``n``
    values (0: not fitted)."""

    loc: float
    scale: float
    n: int = 0

    @staticmethod
    def fit(maxima: np.ndarray) -> Gumbel:
        x = np.asarray(maxima, dtype=float)
        x = x[np.isfinite(x)]
        scale = max(float(np.std(x, ddof=1)) * math.sqrt(6.0) / math.pi, 1e-3) if len(x) > 1 else 0.5
        return Gumbel(float(np.mean(x)) - EULER_GAMMA * scale if len(x) else 3.0, scale, len(x))

    def isf(self, alpha: float) -> float:
        """Value exceeded with probability alpha."""
        return self.loc - self.scale * math.log(-math.log1p(-alpha))

    def isf_se(self, alpha: float) -> float:
        """Monte Carlo standard error of ``isf(alpha)`` fitted by moments to ``n`` draws
        of this law (inf when not fitted). The quantile is m + c s (sample mean m, sample
        sd s, c = sqrt(6)/pi (-ln(-ln(1 - alpha)) - Euler's gamma)); by the delta method
        var = sigma^2 / n (1 + c g1 + c^2 (b2 - 1) / 4) with the Gumbel law's skewness
        g1 = 1.1395 and kurtosis b2 = 5.4 (var m = sigma^2/n, var s = sigma^2 (b2 - 1)/(4n),
        cov(m, s) = g1 sigma^2/(2n)): 3.92 sigma / sqrt(n) at alpha 0.01, 0.14 in z for
        100 replicates of a map's max |z|."""
        if self.n < 2:
            return math.inf
        c = math.sqrt(6.0) / math.pi * (-math.log(-math.log1p(-alpha)) - EULER_GAMMA)
        sigma = self.scale * math.pi / math.sqrt(6.0)
        return sigma * math.sqrt((1.0 + GUMBEL_SKEW * c + c * c * (GUMBEL_KURTOSIS - 1.0) / 4.0) / self.n)

    def sf(self, x: float) -> float:
        """P(max > x)."""
        return float(-math.expm1(-math.exp(-(x - self.loc) / self.scale)))

    @property
    def median(self) -> float:
        return self.loc - self.scale * math.log(math.log(2.0))


@dataclass(frozen=True)
class Null:
    """Bootstrap null of the map and of the whole-record ADEV."""

    mu: np.ndarray          # T x M ln of the mean avar
    mu_u: np.ndarray        # T x M mean of u = (avar / mean avar)^(1/3)
    sd: np.ndarray          # M pooled sd of u
    gumbel: Gumbel          # law of max |z| over the map
    mu_whole: np.ndarray    # M'
    mu_u_whole: np.ndarray  # M'
    sd_whole: np.ndarray    # M'
    gumbel_whole: Gumbel
    n_replicates: int
    alpha: float
    #: candidate kind -> its chance bar from the replicates (scan_null; empty: the GLS's own law)
    scan_bars: dict = field(default_factory=dict)
    #: candidate kind -> the Monte Carlo standard error of its chance bar
    scan_bar_se: dict = field(default_factory=dict)
    #: the replicates' seed (bootstrap.replicate_seeds) and what each gave (cells B x T x M,
    #: whole B x M' ln avar, candidate gains): a bootstrap extended with more replicates
    #: (bootstrap.extended) continues them
    seed: int = 0
    cells: np.ndarray | None = field(default=None, repr=False, compare=False)
    whole: np.ndarray | None = field(default=None, repr=False, compare=False)
    gains: tuple = field(default=(), repr=False, compare=False)

    @property
    def threshold(self) -> float:
        return self.gumbel.isf(self.alpha)

    @property
    def threshold_whole(self) -> float:
        return self.gumbel_whole.isf(self.alpha)

    @property
    def threshold_se(self) -> float:
        """Monte Carlo standard error of ``threshold`` (Gumbel.isf_se)."""
        return self.gumbel.isf_se(self.alpha)

    @property
    def threshold_whole_se(self) -> float:
        return self.gumbel_whole.isf_se(self.alpha)


def _pooled_sd(L: np.ndarray, mu: np.ndarray) -> np.ndarray:
    d = L - mu[None]
    axes = tuple(i for i in range(d.ndim) if i != d.ndim - 1)
    with warnings.catch_warnings():          # cells with no data at all (gaps, platform motion): NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        v = np.nanmean(d ** 2, axis=axes)
    return np.sqrt(np.maximum(v, 1e-12))


def build_null(cells: np.ndarray, whole: np.ndarray, alpha: float = 0.01) -> Null:
    """Null from B replicates: ``cells`` (B x T x M) and ``whole`` (B x M') ln avar.

    Cells are compared on the Wilson-Hilferty scale u = (avar / mean avar)^(1/3), on
    which a scaled chi-square is close to normal even with 3-5 degrees of freedom
    (ln avar has a long lower tail there, which would make deficits at long taus
    false alarms)."""
    B = cells.shape[0]
    if B < 8:
        raise ValueError("need at least 8 bootstrap replicates")

    def prep(L):
        with warnings.catch_warnings(), np.errstate(invalid="ignore", over="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)     # cells with no data: NaN
            mu = np.log(np.nanmean(np.exp(L - np.nanmax(L, axis=0)), axis=0)) + np.nanmax(L, axis=0)
            U = np.exp((L - mu) / 3.0)
            mu_u = np.nanmean(U, axis=0)
        sd = _pooled_sd(U, mu_u) * math.sqrt(B / (B - 1.0))
        return mu, mu_u, sd, U

    mu, mu_u, sd, U = prep(cells)
    mu_w, mu_uw, sd_w, Uw = prep(whole)
    infl = math.sqrt(1.0 + 1.0 / B)
    loo = B / (B - 1.0)  # U_b - mean_{-b} = B/(B-1) (U_b - mean)
    zc = loo * (U - mu_u[None]) / (sd * infl)
    zw = loo * (Uw - mu_uw[None]) / (sd_w * infl)
    maxc = np.nanmax(np.abs(zc).reshape(B, -1), axis=1)
    maxw = np.nanmax(np.abs(zw), axis=1)
    return Null(mu, mu_u, sd, Gumbel.fit(maxc), mu_w, mu_uw, sd_w, Gumbel.fit(maxw), B, alpha,
                cells=cells, whole=whole)


def undecided(z: np.ndarray, z_whole: np.ndarray, null: Null, n_se: float) -> bool:
    """Whether the Monte Carlo error of the null's thresholds may decide that the map
    (``z``) or the whole-record ADEV (``z_whole``) shows a mismatch: the family's largest
    |z| lies above its threshold by less than ``n_se`` standard errors
    (``Null.threshold_se``), a region that more replicates could remove. A near miss is
    not confirmed (explain names nothing it has not shown beyond chance: more replicates
    could only add a region the first draw did not need), nor a family whose largest
    |z| is clear of that band, whatever its weaker regions: their extent is a detail of
    a mismatch already shown."""
    for zz, thr, se in ((z, null.threshold, null.threshold_se), (z_whole, null.threshold_whole,
                                                                  null.threshold_whole_se)):
        a = np.abs(zz[np.isfinite(zz)])
        if a.size and thr <= float(a.max()) < thr + n_se * se:
            return True
    return False


def zscores(cell: np.ndarray, whole: np.ndarray, null: Null) -> tuple[np.ndarray, np.ndarray]:
    """z of the recording's map cells (T x M) and whole-record taus (M')."""
    infl = math.sqrt(1.0 + 1.0 / null.n_replicates)
    with np.errstate(over="ignore", invalid="ignore"):
        u = np.exp((cell - null.mu) / 3.0)
        uw = np.exp((whole - null.mu_whole) / 3.0)
    return (u - null.mu_u) / (null.sd * infl), (uw - null.mu_u_whole) / (null.sd_whole * infl)


@dataclass(frozen=True)
class Region:
    """A connected set of flagged cells: time span (s), tau band (s), sign (+1: the
    recording is noisier than the model), ADEV ratio recording / model (geometric mean
    over the region), largest |z| and family-wise p-value; ``whole_record`` for the
    whole-record ADEV test; ``cells`` the flagged (window, tau) index pairs."""

    t_start_s: float
    t_end_s: float
    tau_min_s: float
    tau_max_s: float
    sign: int
    ratio: float
    max_abs_z: float
    p_value: float
    whole_record: bool
    cells: tuple[tuple[int, int], ...] = ()
    t_peak_s: float | None = None
    span_s: tuple[float, float] | None = None  # the flagged windows' span, before locate()
    tau_peak_s: float | None = None

    def as_json(self) -> dict:
        out: dict[str, object] = {"t_start_s": round(self.t_start_s, 6), "t_end_s": round(self.t_end_s, 6),
               "tau_min_s": self.tau_min_s, "tau_max_s": self.tau_max_s, "ratio": round(self.ratio, 4),
               "p_value": float(f"{self.p_value:.3g}"),
               "t_peak_s": None if self.t_peak_s is None else round(self.t_peak_s, 6),
               "sign": "excess" if self.sign > 0 else "deficit",
               "max_abs_z": round(self.max_abs_z, 2), "whole_record": self.whole_record,
               "n_cells": len(self.cells)}
        if self.tau_peak_s is not None:
            out["tau_peak_s"] = self.tau_peak_s
        if self.span_s is not None:
            out["windows_span_s"] = [round(self.span_s[0], 6), round(self.span_s[1], 6)]
        return out


def find_regions(z: np.ndarray, z_whole: np.ndarray, null: Null, grid: Grid) -> list[Region]:
    """Connected regions of the map above the family-wise threshold, strongest first,
    then the whole-record tau bands above theirs (they cannot say when), strongest
    first. The ADEV ratio is recovered from z."""
    out: list[Region] = []
    infl = math.sqrt(1 + 1 / null.n_replicates)
    with np.errstate(invalid="ignore", divide="ignore"):
        lnratio = 3.0 * np.log(np.maximum(null.mu_u + z * null.sd * infl, 1e-12))
        lnratio_w = 3.0 * np.log(np.maximum(null.mu_u_whole + z_whole * null.sd_whole * infl, 1e-12))
    zz = np.nan_to_num(z)
    thr = null.threshold
    for sign in (1, -1):
        lab, k = ndimage.label(sign * zz > thr)
        for r in range(1, k + 1):
            wi, mi = np.nonzero(lab == r)
            vals = z[wi, mi]
            d = lnratio[wi, mi]
            zmax = float(np.max(np.abs(vals)))
            out.append(Region(
                grid.t0_s + grid.starts[wi.min()] / grid.sample_rate_hz,
                grid.t0_s + (grid.starts[wi.max()] + grid.window_n) / grid.sample_rate_hz,
                float(grid.tau_s[mi.min()]), float(grid.tau_s[mi.max()]), sign,
                float(np.exp(np.mean(d) / 2.0)), zmax, max(null.gumbel.sf(zmax), 1e-16), False,
                tuple(zip(wi.tolist(), mi.tolist(), strict=True)),
                tau_peak_s=float(grid.tau_s[mi[int(np.argmax(np.abs(vals)))]])))
    zw = np.nan_to_num(z_whole)
    thr_w = null.threshold_whole
    for sign in (1, -1):
        lab, k = ndimage.label(sign * zw > thr_w)
        for r in range(1, k + 1):
            mi = np.flatnonzero(lab == r)
            d = lnratio_w[mi]
            zmax = float(np.max(np.abs(z_whole[mi])))
            out.append(Region(grid.t0_s, grid.t0_s + grid.n / grid.sample_rate_hz, float(grid.tau_whole_s[mi.min()]),
                              float(grid.tau_whole_s[mi.max()]), sign, float(np.exp(np.mean(d) / 2.0)), zmax,
                              max(null.gumbel_whole.sf(zmax), 1e-16), True,
                              tau_peak_s=float(grid.tau_whole_s[mi[int(np.argmax(np.abs(z_whole[mi])))]])))
    out.sort(key=lambda r: (r.whole_record, -r.max_abs_z))  # time-resolved first: they say when
    return out


def local_avar_ratio(y: np.ndarray, valid: np.ndarray, m: int, level: np.ndarray | float, smooth: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Matched time-domain scan at one tau: the Allan terms (mean of y over [i+m, i+2m)
    minus mean over [i, i+m))^2 / 2 for every start i, averaged over ``smooth``
    consecutive starts, divided by the model's Allan variance ``level`` at that tau (one
    value per start, or one for all). Returns (ratio, number of valid terms averaged),
    both length n - 2m + 1; 1 means "as noisy as the model". Terms touching an invalid
    sample are left out. Each record-length temporary is let go once used (memory)."""
    ok = valid & np.isfinite(y)
    S = np.concatenate(([0.0], np.cumsum(np.where(ok, y, 0.0))))
    bad = np.concatenate(([0], np.cumsum(~ok)))
    del ok
    k = len(y) - 2 * m + 1
    d = (S[2 * m:2 * m + k] - 2.0 * S[m:m + k] + S[:k]) / m
    del S
    good = (bad[2 * m:2 * m + k] - bad[:k]) == 0
    del bad
    a = np.where(good, 0.5 * d * d / level, 0.0)
    del d
    ca = np.concatenate(([0.0], np.cumsum(a)))
    del a
    cg = np.concatenate(([0], np.cumsum(good)))
    del good
    i = np.arange(k)
    lo = np.clip(i - smooth // 2, 0, k)
    hi = np.clip(i - smooth // 2 + smooth, 0, k)
    del i
    cnt = cg[hi] - cg[lo]
    del cg
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt > 0, (ca[hi] - ca[lo]) / cnt, np.nan), cnt


def locate(regions: list[Region], y: np.ndarray, valid: np.ndarray, grid: Grid, null: Null) -> list[Region]:
    """Each region located at the resolution the data allows, by a matched time-domain
    scan at the tau of its strongest cell (:func:`local_avar_ratio`, averaged over
    max(8 m, n/256) Allan terms, at most half a window): ``t_peak_s`` is the time of the
    strongest local excess (or deficit); a time-resolved region's span narrows to the
    stretch around that peak where the local excess Allan variance is at least half its
    peak value (full width at half maximum; for a deficit, half its deepest drop),
    never beyond the flagged windows (kept as ``span_s``). A whole-record region keeps
    the whole record as its span."""
    return [_locate_one(r, y, valid, grid, null) for r in regions]


def _locate_one(r: Region, y: np.ndarray, valid: np.ndarray, grid: Grid, null: Null) -> Region:
    sample_rate_hz = grid.sample_rate_hz
    n = grid.n
    if r.whole_record:
        j = int(np.argmin(np.abs(grid.tau_whole_s - r.tau_peak_s)))
        m = int(grid.m_whole[j])
        if n - 2 * m + 1 < 1:
            return r
        level: np.ndarray | float = float(np.exp(null.mu_whole[j]))
    else:
        j = int(np.argmin(np.abs(grid.tau_s - r.tau_peak_s)))
        m = int(grid.m[j])
        mu = null.mu[:, j]
        okw = np.isfinite(mu)
        if not okw.any() or n - 2 * m + 1 < 1:
            return r
        t_terms = np.arange(n - 2 * m + 1) + m  # sample index at each term's centre
        centres = grid.starts + (grid.window_n - 1) / 2.0
        level = np.exp(np.interp(t_terms, centres[okw], mu[okw]))
        del t_terms
    smooth = int(min(max(8 * m, n // 256, 16), max(grid.window_n // 2, 16)))
    ratio, _ = local_avar_ratio(y, valid, m, level, smooth)
    del level
    t_lo, t_hi = r.t_start_s, r.t_end_s
    i = np.arange(len(ratio))
    start_s = grid.t0_s + i / sample_rate_hz
    inside = (start_s >= t_lo - 1e-9) & (start_s + 2 * m / sample_rate_hz <= t_hi + 1e-9) & np.isfinite(ratio)
    if not inside.any():
        return r
    sel = np.flatnonzero(inside)
    dev = r.sign * (ratio[sel] - 1.0)
    k = int(np.argmax(dev))
    peak = sel[k]
    t_peak = grid.t0_s + (peak + m) / sample_rate_hz
    if r.whole_record or dev[k] <= 0:
        return replace(r, t_peak_s=t_peak, tau_peak_s=m / sample_rate_hz)
    # the run of consecutive starts around the peak with at least half the peak's excess
    stop = ~(dev >= 0.5 * dev[k]) | np.r_[False, np.diff(sel) != 1]  # a start that ends the run
    brk = np.flatnonzero(stop[: k + 1])
    a = int(brk[-1]) + (0 if dev[brk[-1]] >= 0.5 * dev[k] else 1) if len(brk) else 0
    after = np.flatnonzero(stop[k + 1:])
    b = k + int(after[0]) if len(after) else len(sel) - 1
    t0 = max(t_lo, grid.t0_s + (sel[a] - smooth // 2) / sample_rate_hz)
    t1 = min(t_hi, grid.t0_s + (sel[b] - smooth // 2 + smooth + 2 * m) / sample_rate_hz)
    return replace(r, t_start_s=t0, t_end_s=t1, t_peak_s=t_peak, tau_peak_s=m / sample_rate_hz, span_s=(t_lo, t_hi))


#: Power of the score's smooth maximum of its four figures (and of the axes' scores).
SCORE_POWER = 8.0

#: A score at or below this is within chance: no null record explained against its true
#: model scored above it (0 of 200, validation/calibration.py; docs/explain.md "The null sweep").
CHANCE_SCORE = 1.5


def smooth_max(values) -> float:
    """The power mean (mean of c^SCORE_POWER)^(1/SCORE_POWER) of non-negative figures:
    between n^(-1/SCORE_POWER) x and 1 x the largest (0.84 x for four)."""
    c = np.asarray(values, dtype=float)
    top = float(np.max(c)) if c.size else 0.0
    return top * float(np.mean((c / top) ** SCORE_POWER)) ** (1.0 / SCORE_POWER) if top > 0 else 0.0


@dataclass(frozen=True)
class Score:
    """The goodness-of-fit figure (docs/explain.md): a smooth maximum - the power mean
    (mean of c^8)^(1/8), between 0.84 x and 1 x the largest - of
    - ``rms_map``: root-mean-square z over the map cells (1 under the null),
    - ``max_map``: the map's largest |z| over its null median (Gumbel fit),
    - ``spikes``: the spike test's largest |z| over the median largest |z| of as many
      independent normals,
    - ``tests``: the strongest matched test of a missing effect (every candidate of the
      catalogue fitted to the residual but a kind the map contradicted,
      analysis.matched_tests_figure), sqrt(LR statistic / BIC penalty k ln n).
    Each is about 1 or below when the model explains the recording; no null record of
    validation/calibration.py scored above 1.5 (0 of 200, docs/explain.md "The null
    sweep"). (The whole-record ADEV test has too few taus for a stable ratio; its
    findings are reported as mismatch regions and are covered by the matched tests.)"""

    rms_map: float
    max_map: float
    spikes: float
    tests: float

    @property
    def value(self) -> float:
        # smooth so that an effect that lowers any one figure (and raises none more) lowers
        # the score: a plain maximum ignores an effect that fixes a figure below the top
        return smooth_max([self.rms_map, self.max_map, self.spikes, self.tests])

    def as_json(self) -> dict:
        return {k: round(getattr(self, k), 3) for k in ("rms_map", "max_map", "spikes", "tests")}


def score(z: np.ndarray, null: Null, spike_ratio: float, tests: float) -> Score:
    """Score of a recording's z-map against its null (see :class:`Score`)."""
    zm = z[np.isfinite(z)]
    return Score(float(np.sqrt(np.mean(zm ** 2))) if len(zm) else 0.0,
                 float(np.max(np.abs(zm))) / null.gumbel.median if len(zm) else 0.0,
                 float(spike_ratio), float(tests))


def compare_maps(cell_a: np.ndarray, cell_b: np.ndarray, null: Null) -> np.ndarray:
    """z of the difference of two independent records' map cells (ln avar), on the
    null's u scale with the bootstrap spread: (u_a - u_b) / (sd sqrt(2)). Its largest
    |z| has (close to) the map's null law, so
    a record is "inside the bootstrap bands" of another when it stays below
    ``null.threshold`` (used to check that a re-simulation of the fitted model
    reproduces the recording)."""
    with np.errstate(over="ignore", invalid="ignore"):
        ua = np.exp((cell_a - null.mu) / 3.0)
        ub = np.exp((cell_b - null.mu) / 3.0)
    return (ua - ub) / (null.sd * math.sqrt(2.0))
