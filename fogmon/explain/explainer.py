"""`fogmon explain` end to end (docs/explain.md): residual of the recording against the
model's deterministic part, bootstrap null of the model's stochastic part, mismatch
map, forward selection of candidate physics with BIC and a held-out check, then the
map again against the fitted model.

Bootstrap cost (the part that dominates): each replicate is one run of the simulator's
stochastic part `--like` the recording (bias, rotation and mean-type effects are left
out: they do not change the null of a residual) and one pass of the DAVAR engine's
compensated kernels for the map and the whole-record ADEV (no EDF work). Mean-type
effects and an outlier population (its outliers are replaced in the residual) never
change the null, so accepting them reuses it; only noise-type effects
(markov, bandwidth, vibration/temperature noise) trigger a new bootstrap. The
replicate count adapts to the record length (100 up to 1e5 samples, 60 up to 4e5,
else 40) and the family-wise threshold comes from a Gumbel law fitted to the
replicates' max |z|, so 40 replicates give a usable 1 % threshold; replicates run on
all cores.
"""
from __future__ import annotations

import functools
import math
import multiprocessing as mp
import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from fogmon.errors import FogmonError
from fogmon.explain import catalogue, detectors, mismatch
from fogmon.explain.fitting import Whittle, calibrate_psd, model_psd, rfft_omega
from fogmon.formats.recording import Recording
from fogmon.motion import find_motion, motion_mask
from fogmon.sim import effects as fx
from fogmon.sim.model import EFFECT_KINDS, SensorModel, validate_model
from fogmon.sim.noise import ramp_dph
from fogmon.sim.simulate import iter_simulate

#: how many times a kind may be added (several spectral lines are common)
MAX_PER_KIND = {"periodic": 4, "bias_step": 2, "vibration_lines": 2}
#: kinds not tried against the baseline (no --model): its coefficients are the
#: recording's own, so a corrected [noise] would not be a finding
BASELINE_EXCLUDED = ("noise",)


@dataclass
class Options:
    """Map window (s, default duration/8), bootstrap replicates (default by length),
    family-wise significance, seed, effect budget, worker processes."""

    window_s: float | None = None
    n_boot: int | None = None
    alpha: float = 0.01
    seed: int = 12345
    max_effects: int = 8
    workers: int = 0  # 0: os.cpu_count()


@dataclass
class Analysis:
    """One comparison of a residual with a null: ln avar of the map and whole record,
    z-scores, regions and score."""

    cell: np.ndarray
    whole: np.ndarray
    z: np.ndarray
    z_whole: np.ndarray
    regions: list
    score: mismatch.Score
    null: mismatch.Null


@dataclass
class Accepted:
    """An accepted effect with its selection statistics and per-effect scores."""

    cand: catalogue.Candidate
    bic_gain: float
    heldout: str
    score_before: float
    score_after: float


@dataclass
class Result:
    recording: Recording
    model: SensorModel
    fitted: SensorModel
    grid: mismatch.Grid
    t_s: np.ndarray
    valid: np.ndarray
    residual_before: np.ndarray
    residual_after: np.ndarray
    before: Analysis
    after: Analysis
    accepted: list[Accepted]
    rejected: list[tuple[str, float, str]] = field(default_factory=list)
    n_boot: int = 0
    baseline: bool = False
    warnings: list[dict] = field(default_factory=list)
    #: the regions left after (of ``after``) that a ``nonstationary`` warning names
    nonstationary: list[mismatch.Region] = field(default_factory=list)

    @property
    def deterministic_fit(self) -> np.ndarray:
        """Sum of the fitted mean-type effects (deg/h) on the grid."""
        out = np.zeros(len(self.t_s))
        for a in self.accepted:
            if a.cand.rate is not None:
                out += a.cand.rate
        return out


# ---------------------------------------------------------------- preparation
def check_inputs(rec: Recording, model: SensorModel, window_s: float | None) -> None:
    """One-line errors for the bad inputs of issue 6: sample-rate mismatch, aux channel
    missing for a model effect, recording shorter than the map window."""
    fs_r, fs_m = rec.sample_rate_hz, float(model.sample_rate_hz)
    if abs(fs_r - fs_m) > 1e-3 * fs_m:
        raise FogmonError(f"{rec.name}: sample rate {fs_r:g} Hz does not match the model's "
                          f"[sensor] sample_rate_hz = {fs_m:g} Hz")
    for i, e in enumerate(model.effects):
        need = EFFECT_KINDS[e.kind].aux
        if need and need not in rec.aux:
            raise FogmonError(f"model effect #{i + 1} ({e.kind}) needs the aux channel {need!r}, which "
                              f"{rec.name} lacks (columns: {', '.join(['time_s', 'rate_dph', *rec.aux])})")


def _grid_arrays(rec: Recording):
    blk = rec.to_block()
    valid = blk.valid.copy()
    t = blk.t_s
    aux = {}
    for k, a in blk.aux.items():
        ok = np.isfinite(a)
        aux[k] = a if ok.all() else np.interp(t, t[ok], a[ok])
    return t, blk.rate_dph, valid, aux


def deterministic_dph(model: SensorModel, t: np.ndarray, aux: dict, sample_rate_hz: float) -> np.ndarray:
    """The model's deterministic rate (deg/h): bias + 3600 rot_dps + R ramp + mean-type effects."""
    det = np.full(len(t), float(model.bias_dph))
    if "rot_dps" in aux:
        det += 3600.0 * aux["rot_dps"]
    if model.noise.R_dphh:
        det += ramp_dph(model.noise.R_dphh, t - t[0])
    for e in model.effects:
        if EFFECT_KINDS[e.kind].nature == "mean":
            det += fx.mean_rate_dph(e, t, aux, sample_rate_hz)
    return det


def stochastic_part(model: SensorModel) -> SensorModel:
    """The model without bias, R ramp and mean-type effects: what the null simulates."""
    nz = replace(model.noise, R_dphh=0.0)
    eff = [e for e in model.effects if EFFECT_KINDS[e.kind].nature != "mean"]
    return SensorModel(model.sample_rate_hz, 0.0, nz, eff)


# ---------------------------------------------------------------- bootstrap
#: Progress callback: ``progress(stage, done, total)``; total 0 announces a stage, else
#: ``done`` of ``total`` steps of it are complete.
Progress = Callable[[str, int, int], None]


def _replicate(model: SensorModel, like: Recording, grid: mismatch.Grid, seed) -> tuple[np.ndarray, np.ndarray]:
    """ln avar of the map cells and the whole record of one simulation of ``model``."""
    r = np.concatenate([b.rate_dph for b in iter_simulate(model, like=like, seed=int(seed), chunk_samples=1 << 18)])
    return mismatch.log_avar(r, np.isfinite(r), grid)


_SHARED: tuple = ()  # (model, like, grid) in a bootstrap worker process, inherited by fork


def _init_worker(shared: tuple) -> None:
    global _SHARED
    _SHARED = shared


def _replicate_in_worker(seed) -> tuple[np.ndarray, np.ndarray]:
    model, like, grid = _SHARED
    return _replicate(model, like, grid, seed)


def bootstrap(stoch: SensorModel, like: Recording, grid: mismatch.Grid, n_boot: int, seed: int,
              alpha: float, workers: int, progress: Progress | None = None) -> mismatch.Null:
    """Parametric bootstrap null: ``n_boot`` simulations of ``stoch`` like the recording,
    reported to ``progress`` replicate by replicate."""
    seeds = np.random.SeedSequence(seed).generate_state(n_boot)
    nw = max(1, min(workers or os.cpu_count() or 1, n_boot))
    report = progress or (lambda stage, done, total: None)
    parts = []
    if nw == 1 or grid.n * n_boot < 2_000_000:
        for s in seeds:
            parts.append(_replicate(stoch, like, grid, s))
            report("bootstrap", len(parts), n_boot)
    else:
        with ProcessPoolExecutor(nw, mp_context=mp.get_context("fork"), initializer=_init_worker,
                                 initargs=((stoch, like, grid),)) as ex:
            for part in ex.map(_replicate_in_worker, seeds):
                parts.append(part)
                report("bootstrap", len(parts), n_boot)
    return mismatch.build_null(np.array([c for c, _ in parts]), np.array([w for _, w in parts]), alpha)


def default_n_boot(n: int) -> int:
    return 100 if n <= 100_000 else 60 if n <= 400_000 else 40


# ---------------------------------------------------------------- analysis
def _whittle(stoch: SensorModel, ctx_aux: dict, t: np.ndarray, valid: np.ndarray, y: np.ndarray):
    """The context of the candidates: the model PSD calibrated to the residual over the
    model's pass band (``catalogue.in_passband``), and no weight outside it: an octave
    band holding a filter's zero would otherwise take its factor from bins where the
    model is floored, and the bins next to them would show a false excess."""
    n = len(y)
    omega = rfft_omega(n)
    S = model_psd(stoch, omega, n, catalogue.white_level_rms_dpsh(stoch, t, ctx_aux))
    S = np.maximum(S, 1e-4 * np.median(S[1:]))  # a PSD near 0 must not give one bin all the weight
    yy = np.where(valid, y, 0.0)
    Yf = np.fft.rfft(yy)
    keep = catalogue.in_passband(stoch, omega)
    S_cal = np.full(len(S), np.inf)
    S_cal[keep] = calibrate_psd(S[keep], Yf[keep], n)  # a low-pass's pass band: the bins 0..K
    wh = Whittle(S_cal, n, valid)
    # The circular DFT joins the record's last sample to its first; for blue
    # (quantization) noise the angle mismatch there is a one-sample rate spike at index 0
    # that the GLS sees clearly: project it out (a nuisance regressor) before any test.
    amp0 = float(detectors.spike_scan(wh, Yf)[0][0])
    yy = yy.copy()
    yy[0] -= amp0
    Yf = Yf - amp0
    return catalogue.Context(t, ctx_aux, valid, float(stoch.sample_rate_hz), yy, stoch, wh, Yf)


def matched_tests_figure(cands: list[catalogue.Candidate], penalty: float, contradicted: set[str]) -> float:
    """The score's ``tests``: the strongest candidate's sqrt(gain / (k ln n)), candidates
    of a kind the map contradicted (``contradicted``: added, it opened a whole-record
    deficit, ``_judge``) left out - their statistic measured a misfit their shape does
    not describe, and the map's own figures keep that misfit."""
    return max([math.sqrt(max(c.gain, 0.0) / (c.k * penalty)) for c in cands if c.kind not in contradicted],
               default=0.0)


def analyse(y: np.ndarray, ctx: catalogue.Context, null: mismatch.Null, grid: mismatch.Grid,
            cands: list[catalogue.Candidate], contradicted: set[str]) -> Analysis:
    """Map, regions and score of residual ``y`` (candidates: the matched tests run on it,
    those of the ``contradicted`` kinds not counted, ``matched_tests_figure``)."""
    cell, whole = mismatch.log_avar(np.where(ctx.valid, y, np.nan), ctx.valid, grid)
    z, zw = mismatch.zscores(cell, whole, null)
    _, zs = catalogue.spike_scan(ctx)
    nv = int(ctx.valid.sum())
    spike_ratio = float(np.max(np.abs(zs))) / detectors.expected_max_abs_z(nv) if nv else 0.0
    regions = mismatch.find_regions(z, zw, null, grid)
    tests = matched_tests_figure(cands, ctx.penalty, contradicted)
    return Analysis(cell, whole, z, zw, regions, mismatch.score(z, null, spike_ratio, tests), null)


def rescored(a: Analysis, cands: list[catalogue.Candidate], penalty: float, contradicted: set[str]) -> Analysis:
    """``a`` with its score's ``tests`` taken again without the ``contradicted`` kinds."""
    return replace(a, score=replace(a.score, tests=matched_tests_figure(cands, penalty, contradicted)))


def candidates(ctx: catalogue.Context, counts: dict) -> list[catalogue.Candidate]:
    """Every applicable catalogue entry fitted to the current residual, best BIC first
    (refused kinds included: they still measure what is missing, the score's ``tests``,
    unless the map contradicted them, ``matched_tests_figure``)."""
    out = []
    for kind, fn in {**catalogue.MEAN_CANDIDATES, **catalogue.NOISE_CANDIDATES}.items():
        if counts.get(kind, 0) >= MAX_PER_KIND.get(kind, 1):
            continue
        c = fn(ctx)
        if c is not None:
            out.append(c)
    out.sort(key=lambda c: -c.bic_gain(ctx.penalty))
    return out


def tiers(cands: list[catalogue.Candidate]) -> list[list[catalogue.Candidate]]:
    """Selection order: effects tied to time structure or an aux channel (mean-type,
    white-level) first; the broad spectral noise terms (markov, bandwidth) only when
    none of those passes - a spectral term can always soak up part of a deterministic
    signal's power, never the other way round. Corrected IEEE-952 coefficients (the
    ``noise`` kind) compete in the first tier by BIC gain - every GLS test there assumes
    the model's noise, so a wrong B or N can fake a step or a ramp - but never ahead of
    a white-level effect: when an aux channel co-varies with the white level, the
    physical effect is preferred over a corrected N."""
    first = [c for c in cands if c.nature in ("mean", "white_level", "coefficients") or _subtracted(c)]
    levels = [c for c in first if c.nature == "white_level"]
    coef = [c for c in first if c.nature == "coefficients"]
    if coef and levels:  # the coefficient correction moves behind the last white-level candidate
        first = [c for c in first if c.nature != "coefficients"]
        at = first.index(levels[-1]) + 1
        first[at:at] = coef
    return [first, [c for c in cands if c not in first]]


def _heldout_mean(ctx: catalogue.Context, X: np.ndarray) -> tuple[bool, str]:
    """Fit on one half of the record, predict the other: wherever the half-fit is itself
    significant (chi2 gain > 9) and predicts a visible effect in the other half
    (expected chi2 > 9), the other half's chi-square must drop."""
    n = ctx.n
    half = np.arange(n) < n // 2
    notes = []
    ok = True

    def centred(m):  # each half gets its own intercept (the bias is free in each half)
        v = ctx.valid & m
        return (np.where(v, ctx.y - ctx.y[v].mean(), 0.0), np.where(v[:, None], X - X[v].mean(axis=0), 0.0), v)

    for fit_m, test_m, name in ((half, ~half, "second"), (~half, half, "first")):
        yf, Xf, vf = centred(fit_m)
        wf = Whittle(ctx.wh.S, n, vf)
        fit = wf.gls(wf.fft(Xf), wf.fft(yf))
        if fit.chi2_gain < 9.0:
            notes.append(f"{name} half: n/a (not determined by the other half)")
            continue
        yt, Xt, vt = centred(test_m)
        wt = Whittle(ctx.wh.S, n, vt)
        XtF = wt.fft(Xt)
        expected = wt.chi2(XtF @ fit.beta)
        if expected < 9.0:
            notes.append(f"{name} half: n/a (effect not visible there)")
            continue
        g = wt.gain_of(fit.beta, XtF, wt.fft(yt))
        notes.append(f"{name} half: chi2 drop {g:.1f} (expected {expected:.1f})")
        ok &= g > 0
    return ok, "; ".join(notes)


def _heldout(ctx: catalogue.Context, c: catalogue.Candidate) -> tuple[bool, str]:
    if c.design is not None:
        return _heldout_mean(ctx, c.design)
    if c.heldout is not None:
        res = c.heldout()
        ok = all(g > 0 for g, exp in res if exp >= 9.0)
        return ok, "; ".join(f"{h} half: chi2 drop {g:.1f} (expected {e:.1f})"
                             for h, (g, e) in zip(("second", "first"), res, strict=True))
    return True, "n/a (spectral or spike fit on the whole record)"


#: a fitted line this many frequency resolutions 1/T wide is resolved: band-limited
#: noise, not a coherent sinusoid
LINE_RESOLVED_BINS = 4.0


def _inside_line(c: catalogue.Candidate, cands: list[catalogue.Candidate], df_hz: float) -> float | None:
    """Centre (Hz) of a resolved vibration_lines line holding a periodic candidate's
    frequency (within half its -3 dB bandwidth), or None: such a line is one random
    process, which periodic terms would only chase bin by bin."""
    if c.kind != "periodic":
        return None
    f = 1.0 / c.params["period_s"]
    for o in cands:
        if o.kind == "vibration_lines" and o.bic_gain(0.0) > 0:
            for fl, bw in zip(o.params["freq_hz"], o.params["bandwidth_hz"], strict=True):
                if bw >= LINE_RESOLVED_BINS * df_hz and abs(f - fl) <= bw / 2:
                    return float(fl)
    return None


def _new_deficit(before: Analysis, after: Analysis) -> str | None:
    """Tau band (text) of a whole-record deficit region present after a noise-type effect
    was added but not before, or None."""
    old = [(r.tau_min_s, r.tau_max_s) for r in before.regions if r.whole_record and r.sign < 0]
    for r in after.regions:
        if r.whole_record and r.sign < 0 and not any(lo <= r.tau_max_s and r.tau_min_s <= hi for lo, hi in old):
            return f"{r.tau_min_s:.4g}..{r.tau_max_s:.4g}"
    return None


#: Smallest score drop an accepted effect must bring: the report rounds scores to 3
#: decimals, and its invariant is score_after < score_before for every effect.
MIN_SCORE_DROP = 0.002
#: ... and at least this share of the score: the score's figures are ratios to bootstrap
#: estimates (the null's median max |z| from 40..100 replicates is known to 1-2 %), so
#: a smaller change is below what the score resolves, not an improvement (a real MEMS
#: record had a bias step accepted for 5.85 -> 5.84)
MIN_SCORE_DROP_SHARE = 0.01


def _lowers(before: float, after: float) -> bool:
    return after <= before - max(MIN_SCORE_DROP, MIN_SCORE_DROP_SHARE * before)


def _subtracted(c: catalogue.Candidate) -> bool:
    """Whether ``c`` is taken out of the residual (the null stays): a mean-type effect, or
    outliers replaced; other noise-type effects join the stochastic model (their ``rate``,
    a vibration_lines' Wiener estimate, serves --out-corrected only)."""
    return c.nature == "mean" or c.kind == "outliers"


def _try(c: catalogue.Candidate, y, stoch, null, ctx, counts, aux, t, valid, like, grid, B, opt, n_acc, progress,
         contradicted):
    """(residual, stochastic model, null, context, analysis, candidates) with ``c`` added:
    a mean-type effect, or outliers replaced in the residual, is subtracted (same null),
    a noise-type one joins the stochastic model (new bootstrap)."""
    if _subtracted(c):
        y_new, stoch_new, null_new = np.where(valid, y - c.rate, 0.0), stoch, null
    else:
        y_new = y
        if c.corrected_noise is not None:  # the noise kind: corrected coefficients, no new effect
            stoch_new = SensorModel(stoch.sample_rate_hz, 0.0, c.corrected_noise, stoch.effects)
        else:
            base = stoch if c.stoch_base is None else c.stoch_base
            noise = base.noise if c.white_n0_dpsh is None else replace(base.noise, N_dpsh=c.white_n0_dpsh)
            stoch_new = SensorModel(stoch.sample_rate_hz, 0.0, noise, [*base.effects, c.effect()])
        if progress:
            progress(f"bootstrap null with {c.kind} added: {B} simulations", 0, 0)
        null_new = bootstrap(stoch_new, like, grid, B, opt.seed + 7919 * (n_acc + 1), opt.alpha,
                             opt.workers, progress)
    ctx_new = _whittle(stoch_new, aux, t, valid, y_new)
    cands_new = candidates(ctx_new, {**counts, c.kind: counts.get(c.kind, 0) + 1})
    after = analyse(y_new, ctx_new, null_new, grid, cands_new, contradicted)
    return y_new, stoch_new, null_new, ctx_new, after, cands_new


def explain(rec: Recording, model: SensorModel, options: Options | None = None,
            baseline: bool = False, progress: Progress | None = None) -> Result:
    """Compare ``rec`` with ``model``, locate mismatches, select and fit missing physics;
    stages and bootstrap replicates are reported to ``progress``."""
    opt = options or Options()
    report = progress or (lambda stage, done, total: None)
    model = validate_model(model)
    check_inputs(rec, model, opt.window_s)
    t, raw, valid, aux = _grid_arrays(rec)
    sample_rate_hz = rec.sample_rate_hz
    n = len(t)
    grid = mismatch.make_grid(n, sample_rate_hz, opt.window_s, t0_s=float(t[0]), name=rec.name)
    if valid.sum() < MIN_STATIONARY_SHARE * n:
        raise FogmonError(f"{rec.name}: more than {100 * (1 - MIN_STATIONARY_SHARE):.0f} % of the sample grid is "
                          f"missing (gaps)")
    y0 = raw - deterministic_dph(model, t, aux, sample_rate_hz)
    y0 = np.where(valid, y0 - np.nanmean(y0[valid]), 0.0)
    like = Recording(rec.t_s, np.zeros(len(rec.t_s)), {k: v for k, v in rec.aux.items() if k != "rot_dps"},
                     {"sample_rate_hz": repr(sample_rate_hz)}, rec.path)
    B = opt.n_boot or default_n_boot(n)
    stoch = stochastic_part(model)
    report(f"bootstrap null: {B} simulations of the model like the recording", 0, 0)
    null = bootstrap(stoch, like, grid, B, opt.seed, opt.alpha, opt.workers, progress)
    report("mismatch map and candidate effects", 0, 0)
    ctx = _whittle(stoch, aux, t, valid, y0)
    counts: dict[str, int] = {k: MAX_PER_KIND.get(k, 1) for k in BASELINE_EXCLUDED} if baseline else {}
    refused: set[str] = set()
    contradicted: set[str] = set()  # refused kinds whose tests the score no longer counts (matched_tests_figure)
    cands = candidates(ctx, counts)
    cands0 = cands
    before = current = analyse(y0, ctx, null, grid, cands, contradicted)
    y = y0.copy()
    accepted: list[Accepted] = []
    rejected: list[tuple[str, float, str]] = []
    deferred: dict[str, tuple[float, str]] = {}  # kind -> (bic gain, why): retried after an acceptance
    while len(accepted) < opt.max_effects:
        trial_of = functools.partial(_try, y=y, stoch=stoch, null=null, ctx=ctx, counts=counts, aux=aux, t=t,
                                     valid=valid, like=like, grid=grid, B=B, opt=opt, n_acc=len(accepted),
                                     progress=progress, contradicted=contradicted)
        chosen, current = _choose(cands, ctx, current, refused, contradicted, deferred, rejected, trial_of)
        if chosen is None:
            break
        c, bg, note, (y, stoch, null, ctx, after, cands) = chosen
        counts[c.kind] = counts.get(c.kind, 0) + 1
        accepted.append(Accepted(c, bg, note, current.score.value, after.score.value))
        report(f"effect {len(accepted)}: {c.kind} (score {current.score.value:.3g} -> {after.score.value:.3g})", 0, 0)
        current = after
        deferred.clear()
    rejected += [(k, bg, why) for k, (bg, why) in deferred.items()]
    rejected += [(c.kind, c.bic_gain(ctx.penalty), "below the frequency search's chance bar"
                  if c.search_bar > c.k * ctx.penalty else "below the BIC bar") for c in cands
                 if c.bic_gain(ctx.penalty) <= 0 and c.kind not in refused]
    fitted = _fitted_model(model, stoch, accepted)
    accepted.sort(key=lambda a: -a.cand.gain)
    before = rescored(before, cands0, ctx.penalty, contradicted)  # before and after count the same tests
    before = replace(before, regions=mismatch.locate(before.regions, y0, valid, grid, before.null))
    current = replace(current, regions=mismatch.locate(current.regions, y, valid, grid, current.null))
    bursts, named = nonstationary_warnings(current, y, valid, grid)
    return Result(rec, model, fitted, grid, t, valid, y0, y, before, current, accepted, rejected, B, baseline,
                  too_short_warnings(model, grid) + bursts, named)


def _judge(c: catalogue.Candidate, cands: list[catalogue.Candidate], ctx: catalogue.Context, current: Analysis,
           trial_of: Callable) -> tuple[str, float, str, tuple | None]:
    """What the search does with candidate ``c`` (its BIC gain ``bg`` and why): ("stop", ...)
    when bg is not positive (the rest of its tier is no better), ("defer", bg, why) to retry
    it after an acceptance, ("reject", bg, why) for good, ("contradicted", bg, why) for good
    when the map contradicts it (added, it opens a whole-record deficit), or ("accept", bg,
    held-out note, the trial of ``trial_of(c)``)."""
    bg = c.bic_gain(ctx.penalty)
    if bg <= 0:
        return "stop", bg, "", None
    line = _inside_line(c, cands, ctx.sample_rate_hz / ctx.n)
    if line is not None:
        return "defer", bg, (f"its frequency lies inside the narrowband line at {line:.4g} Hz that "
                             f"vibration_lines fits (random vibration, not one coherent sinusoid)"), None
    ok, note = _heldout(ctx, c)
    if not ok:
        return "reject", bg, f"failed the held-out check: {note}", None
    trial = trial_of(c)
    # not for effects with an estimate: subtracted ones, and vibration lines, whose band-pass shape
    # may leave a deficit elsewhere; guarded, real sway lines were refused (docs/explain.md, limits)
    overfit = _new_deficit(current, trial[4]) if c.rate is None else None
    if overfit is not None:
        return "contradicted", bg, (f"makes the model noisier than the recording at tau {overfit} s (the "
                                    f"spectral fit trades long taus for short ones; its test no longer counts "
                                    f"in the score)"), None
    if not _lowers(current.score.value, trial[4].score.value):
        return "defer", bg, (f"does not lower the score ({current.score.value:.3f} -> "
                             f"{trial[4].score.value:.3f}): what it fits is within chance "
                             f"next to what is still missing"), None
    return "accept", bg, note, trial


def _choose(cands: list[catalogue.Candidate], ctx: catalogue.Context, current: Analysis, refused: set[str],
            contradicted: set[str], deferred: dict[str, tuple[float, str]], rejected: list[tuple[str, float, str]],
            trial_of: Callable) -> tuple[tuple | None, Analysis]:
    """The first candidate, tier by tier, that passes every test (``_judge``), as
    (candidate, BIC gain, held-out note, trial), or None when none does; and ``current``
    rescored without the tests of the kinds the map contradicted (the candidates after
    them are judged against that score). Candidates refused or deferred are skipped; what
    is refused, contradicted, deferred or rejected is recorded."""
    for tier in tiers(cands):
        for c in tier:
            if c.kind in refused or c.kind in deferred:
                continue
            verdict, bg, why, trial = _judge(c, cands, ctx, current, trial_of)
            if verdict == "stop":
                break
            if verdict == "defer":
                deferred[c.kind] = (bg, why)
            elif verdict in ("reject", "contradicted"):
                rejected.append((c.kind, bg, why))
                refused.add(c.kind)
                if verdict == "contradicted":
                    contradicted.add(c.kind)
                    current = rescored(current, cands, ctx.penalty, contradicted)
            else:
                return (c, bg, why, trial), current
    return None, current


def _fitted_model(model: SensorModel, stoch: SensorModel, accepted: list[Accepted]) -> SensorModel:
    """The model with the accepted effects: the stochastic part's coefficients (the model's,
    with N0 of a white-level effect and the noise kind's corrections; R is the
    deterministic part's, unchanged), the model's own effects (its noise-type ones as the
    stochastic part holds them: a low-pass level refitted under vibration lines) and
    every accepted effect but the noise kind's."""
    held = iter(stoch.effects)  # stochastic_part keeps the model's noise-type effects first, in order
    own = [e if EFFECT_KINDS[e.kind].nature == "mean" else next(held) for e in model.effects]
    return validate_model(SensorModel(
        model.sample_rate_hz, model.bias_dph, replace(stoch.noise, R_dphh=model.noise.R_dphh),
        [*own, *(a.cand.effect() for a in accepted if a.cand.corrected_noise is None)], dict(model.meta)))


#: explain needs this share of the sample grid present and outside platform motion
MIN_STATIONARY_SHARE = 0.3


def without_motion(rec: Recording) -> tuple[Recording, list[dict]]:
    """``rec`` without its platform-motion samples (they become time gaps) and a
    ``platform_motion`` warning per span (docs/formats.md); FogmonError when too little
    stationary data is left to explain."""
    blk = rec.to_block()
    y = blk.error_rate_dph
    spans = find_motion(blk.t_s, y, blk.valid & np.isfinite(y), rec.sample_rate_hz)
    if not spans:
        return rec, []
    keep = ~motion_mask(rec.t_s, spans)
    share = 1.0 - keep.sum() / len(keep)
    what = "the rate minus 3600 x rot_dps" if "rot_dps" in rec.aux else "the rate"
    if keep.sum() < MIN_STATIONARY_SHARE * len(keep):
        raise FogmonError(f"{rec.name}: platform motion over {100 * share:.0f} % of the record ("
                          + ", ".join(f"{m.t_start_s:.2f}..{m.t_end_s:.2f} s" for m in spans[:5])
                          + (f" and {len(spans) - 5} more" if len(spans) > 5 else "")
                          + "): too little stationary data to explain; fogmon replay shows it, "
                            "--keep-motion analyses it as recorded")
    warnings = [{"kind": "platform_motion", "t_start_s": m.t_start_s, "t_end_s": m.t_end_s,
                 "text": f"{what} moves up to {m.peak_dph:.4g} deg/h from its reference, far beyond the sensor's "
                         f"noise, with no rot_dps to say why (a turntable, a vehicle, a person, the ground): "
                         f"kept out of the analysis (docs/motion.md)"} for m in spans]
    trimmed = Recording(rec.t_s[keep], rec.rate_dph[keep], {k: v[keep] for k, v in rec.aux.items()},
                        dict(rec.meta), rec.path, rec.skipped_rows)
    return trimmed, warnings


#: A slow model term the record cannot test: its share of the model's Allan variance at
#: the longest whole-record tau (duration / 4) is below this.
UNTESTABLE_SHARE = 0.1


def too_short_warnings(model: SensorModel, grid: mismatch.Grid) -> list[dict]:
    """``record_too_short`` warnings (docs/formats.md): a map with fewer than 3 taus
    (window too short to show how the mismatch depends on tau), and model terms the
    record is too short to test - IEEE-952 B, K, R below UNTESTABLE_SHARE of the model's
    Allan variance even at tau = duration / 4, a periodic term with fewer than two
    periods, a Gauss-Markov correlation time beyond duration / 4."""
    from fogmon.davar.theory import coefficients_to_avar_terms

    t0, t1 = grid.t0_s, grid.t0_s + grid.n / grid.sample_rate_hz
    dur = grid.n / grid.sample_rate_hz
    tau_max = float(grid.tau_whole_s[-1])
    out = []

    def warn(text):
        out.append({"kind": "record_too_short", "t_start_s": t0, "t_end_s": t1, "text": text})

    if len(grid.m) < 3:
        warn(f"the map window ({grid.window_s:.6g} s) holds only {len(grid.m)} octave tau(s) up to "
             f"{grid.tau_s[-1]:.6g} s: too few to show how a mismatch depends on tau (use a longer --window-s "
             f"or a longer recording)")
    nz = model.noise
    terms = coefficients_to_avar_terms(nz.Q_arcsec, nz.N_dpsh, nz.B_dph, nz.K_dphsh, nz.R_dphh)
    parts = [float(terms[i]) * tau_max ** float(p) for i, p in enumerate((-2, -1, 0, 1, 2))]
    total = sum(parts)
    for i, (name, value, unit) in enumerate((("B", nz.B_dph, "deg/h"), ("K", nz.K_dphsh, "deg/h/sqrt(h)"),
                                             ("R", nz.R_dphh, "deg/h^2")), start=2):
        if value > 0 and total > 0 and parts[i] < UNTESTABLE_SHARE * total:
            warn(f"the model's {name} = {value:.4g} {unit} is {100 * parts[i] / total:.2g} % of its Allan "
                 f"variance even at the longest tau this {dur:.6g} s record supports ({tau_max:.6g} s = duration/4): "
                 f"the record cannot test it")
    for e in model.effects:
        if e.kind == "periodic" and e.params["period_s"] > dur / 2:
            warn(f"the model's periodic term ({e.params['period_s']:.6g} s) completes fewer than two periods "
                 f"in this {dur:.6g} s record: it cannot be told from a drift")
        if e.kind == "markov" and e.params["tau_c_s"] > tau_max:
            warn(f"the model's Gauss-Markov correlation time ({e.params['tau_c_s']:.6g} s) is beyond the longest "
                 f"tau this {dur:.6g} s record supports ({tau_max:.6g} s)")
    return out


#: A region left after the selection is a non-stationary burst when the residual's rms in
#: the band its taus respond to stands at least this many standard deviations above the
#: record's other spans of its length (detectors.band_rms_burst) and it spans at most
#: BURST_MAX_SHARE of the record
BURST_Z = 3.0
BURST_MAX_SHARE = 0.5


def nonstationary_warnings(after: Analysis, y: np.ndarray, valid: np.ndarray, grid: mismatch.Grid
                           ) -> tuple[list[dict], list[mismatch.Region]]:
    """``nonstationary`` warnings (docs/formats.md) for the excess regions left in
    ``after`` that are band-limited rms bursts of the residual ``y`` (BURST_Z), and for a
    whole-record excess those bursts account for (without their spans the whole-record
    ADEV at its taus is inside the null's threshold); with the regions they name. Such
    excess is non-stationary noise - ground motion, a disturbance - that no stationary
    effect kind models, not missing sensor physics."""
    fs = grid.sample_rate_hz
    out: list[dict] = []
    named: list[mismatch.Region] = []
    spans: list[tuple[int, int]] = []
    for r in after.regions:
        if r.whole_record or r.sign < 0:
            continue
        i0 = max(int(round((r.t_start_s - grid.t0_s) * fs)), 0)
        i1 = min(int(round((r.t_end_s - grid.t0_s) * fs)), grid.n)
        if i1 - i0 > BURST_MAX_SHARE * grid.n:
            continue
        lo, hi = detectors.tau_band_hz(r.tau_min_s, r.tau_max_s, fs)
        b = detectors.band_rms_burst(y, valid, fs, i0, i1, lo, hi)
        if b is None or b.z < BURST_Z:
            continue
        spans.append((i0, i1))
        named.append(r)
        out.append({"kind": "nonstationary", "t_start_s": r.t_start_s, "t_end_s": r.t_end_s,
                    "text": f"the excess at tau {r.tau_min_s:g}..{r.tau_max_s:g} s over t = {r.t_start_s:.6g}.."
                            f"{r.t_end_s:.6g} s is a burst: the residual's rms in the "
                            f"{b.f_lo_hz:.3g}-{b.f_hi_hz:.3g} Hz band (what those taus respond to) is "
                            f"{b.rms_ratio:.2f}x the median of the record's "
                            f"{b.spans_n} other spans of {(i1 - i0) / fs:.4g} s (z = {b.z:.1f}, scatter "
                            f"{b.sd:.2f} in ln rms): non-stationary noise (ground motion, a disturbance) that "
                            f"no stationary effect kind models, not missing sensor physics"})
    if not spans:
        return out, named
    keep = valid.copy()
    for i0, i1 in spans:
        keep[i0:i1] = False
    _, whole = mismatch.log_avar(np.where(keep, y, np.nan), keep, grid)
    _, zw = mismatch.zscores(after.cell, whole, after.null)
    thr = after.null.threshold_whole
    t1 = grid.t0_s + grid.n / fs
    for r in after.regions:
        if not (r.whole_record and r.sign > 0):
            continue
        at = (grid.tau_whole_s >= r.tau_min_s - 1e-12) & (grid.tau_whole_s <= r.tau_max_s + 1e-12)
        z_left = float(np.nanmax(np.abs(zw[at]))) if np.isfinite(zw[at]).any() else float("nan")
        if not z_left < thr:
            continue
        named.append(r)
        out.append({"kind": "nonstationary", "t_start_s": grid.t0_s, "t_end_s": t1,
                    "text": f"the whole-record excess at tau {r.tau_min_s:g}..{r.tau_max_s:g} s (ADEV ratio "
                            f"{r.ratio:.3g}) is the bursts': without their spans the whole-record ADEV there is "
                            f"inside the null (largest |z| {z_left:.2f} < {thr:.2f})"})
    return out, named
