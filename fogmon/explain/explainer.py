"""`fogmon explain` end to end (docs/explain.md): residual of the recording against the
model's deterministic part, bootstrap null of the model's stochastic part (bootstrap),
mismatch map (analysis), forward selection of candidate physics with BIC and a
held-out check (selection), then the map again against the fitted model and the
report's warnings (caveats)."""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from fogmon.errors import FogmonError
from fogmon.explain import mismatch
from fogmon.explain.analysis import Analysis, rescored
from fogmon.explain.bootstrap import Mapper, Progress, bootstrap, default_n_boot
from fogmon.explain.caveats import (
    lookalike_warnings,
    nonstationary_warnings,
    spike_warnings,
    too_short_warnings,
    walk_lookalike_warnings,
)
from fogmon.explain.options import Options
from fogmon.explain.replicas import Replicas
from fogmon.explain.selection import Accepted, Selection, Setting, light
from fogmon.formats.recording import Recording
from fogmon.motion import find_motion, motion_mask
from fogmon.sim import effects as fx
from fogmon.sim.features import channels_of
from fogmon.sim.model import EFFECT_KINDS, SensorModel, validate_model
from fogmon.sim.noise import ramp_dph


@dataclass
class Result:
    """What explain found: the grid's sample times ``t_s`` (s) and ``valid`` mask, the
    residual (deg/h) and its analysis before and after the ``accepted`` effects (largest
    gain first), the ``fitted`` model, the candidates ``rejected`` (kind, BIC gain, why),
    the size of the bootstrap the first map was judged with (``n_boot``, with the
    sequential test's extra replicates) and the report's warnings."""

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
    #: every spike a ``spikes`` warning names (times_s, amplitudes_dph, abs_z: arrays), when
    #: the spike test finds more than chance and no outlier effect was accepted; else None
    spikes: dict | None = None
    #: the record's own fit as ``fogmon replay`` prints it (``report.record_fit`` of the
    #: recording as recorded), set by the caller that had it; None: of ``recording``
    record_fit: dict | None = None

    @property
    def deterministic_fit(self) -> np.ndarray:
        """Sum of the fitted mean-type effects (deg/h) on the grid."""
        out = np.zeros(len(self.t_s))
        for a in self.accepted:
            if a.cand.rate is not None:
                out += a.cand.rate
        return out


def check_inputs(rec: Recording, model: SensorModel, window_s: float | None, where: str = "model") -> None:
    """One-line errors for the bad inputs of issue 6: sample-rate mismatch, aux channel
    missing for a model effect (``where``: the model's name in the message, its file),
    recording shorter than the map window; and a rate that never changes (a stuck output:
    no noise to compare with any model)."""
    fs_r, fs_m = rec.sample_rate_hz, float(model.sample_rate_hz)
    if abs(fs_r - fs_m) > 1e-3 * fs_m:
        raise FogmonError(f"{rec.name}: sample rate {fs_r:g} Hz does not match the model's "
                          f"[sensor] sample_rate_hz = {fs_m:g} Hz")
    for i, e in enumerate(model.effects):
        need = channels_of(e.params["terms"]) if e.kind == "aux_response" else [EFFECT_KINDS[e.kind].aux]
        for c in need:
            if c and c not in rec.aux:
                raise FogmonError(f"{where}: [[effect]] #{i + 1} ({e.kind}) needs the aux channel {c!r}, which "
                                  f"{rec.name} lacks (columns: {', '.join(['time_s', 'rate_dph', *rec.aux])})")
    rec.check_changes()   # after the model's own checks: those name what to fix in the model or the file


def _grid_arrays(rec: Recording):
    """Sample times (s), rate (deg/h), valid mask and gap-filled aux channels on the
    recording's sample grid: a recording without time gaps lends its own arrays (explain
    writes into none of them; a 1e7-sample copy is 80 MB each)."""
    idx = rec.grid_index()
    if len(idx) and int(idx[-1]) + 1 == len(idx) and rec.rate_dph.ndim == 1:
        t, rate = np.asarray(rec.t_s, dtype=np.float64), np.asarray(rec.rate_dph, dtype=np.float64)
        valid, channels = np.isfinite(rate), {k: np.asarray(a, dtype=np.float64) for k, a in rec.aux.items()}
    else:
        blk = rec.to_block()
        t, rate, valid, channels = blk.t_s, blk.rate_dph, blk.valid.copy(), blk.aux
    del idx
    aux = {}
    for k, a in channels.items():
        ok = np.isfinite(a)
        aux[k] = a if ok.all() else np.interp(t, t[ok], a[ok])
    return t, rate, valid, aux


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


def _residual(model: SensorModel, t: np.ndarray, raw: np.ndarray, valid: np.ndarray, aux: dict,
              sample_rate_hz: float) -> np.ndarray:
    """The rate ``raw`` (deg/h) less the model's deterministic part and its mean over the
    ``valid`` samples, 0 where not valid."""
    y = raw - deterministic_dph(model, t, aux, sample_rate_hz)
    return np.where(valid, y - np.nanmean(y[valid]), 0.0)


def stochastic_part(model: SensorModel) -> SensorModel:
    """The model without bias, R ramp and mean-type effects: what the null simulates."""
    nz = replace(model.noise, R_dphh=0.0)
    eff = [e for e in model.effects if EFFECT_KINDS[e.kind].nature != "mean"]
    return SensorModel(model.sample_rate_hz, 0.0, nz, eff)


def explain(rec: Recording, model: SensorModel, options: Options | None = None,
            baseline: bool = False, progress: Progress | None = None, mapper: Mapper | None = None) -> Result:
    """Compare ``rec`` with ``model``, locate mismatches, select and fit missing physics;
    stages and bootstrap replicates are reported to ``progress``; the bootstrap
    replicates run by ``mapper`` (e.g. as Dask tasks; None: on this machine's cores)."""
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
    B = opt.n_boot or default_n_boot(n)
    stoch = stochastic_part(model)
    report(f"bootstrap null: {B} simulations of the model like the recording", 0, 0)
    null = bootstrap(Replicas(stoch, t, aux, valid), grid, B, opt.seed, opt.alpha, opt.workers, progress, mapper)
    report("mismatch map and candidate effects", 0, 0)
    setting = Setting(t, aux, valid, grid, B, opt.seed, opt.alpha, opt.workers, opt.max_effects, progress,
                      mapper, rec.meta)
    # the residual before, taken over by the selection and formed again at the end (memory)
    state = Selection.start(setting, _residual(model, t, raw, valid, aux, sample_rate_hz), stoch, null, baseline)
    # what `before` needs of the first round (its context is let go: memory)
    first_analysis, first_tests = state.fit.analysis, [light(c) for c in state.fit.cands]
    while not state.done:
        state = state.step()
    fit = state.fit
    fitted = _fitted_model(model, fit.stoch, state.accepted)
    accepted = sorted(state.accepted, key=lambda a: -a.cand.gain)
    # before and after count the same tests
    y0 = _residual(model, t, raw, valid, aux, sample_rate_hz)
    before = rescored(first_analysis, first_tests, fit.ctx.penalty, state.contradicted)
    before = replace(before, regions=mismatch.locate(before.regions, y0, valid, grid, before.null))
    y_after = fit.y
    after = replace(fit.analysis,
                    regions=mismatch.locate(fit.analysis.regions, y_after, valid, grid, fit.analysis.null))
    bursts, named = nonstationary_warnings(after, y_after, valid, grid)
    rejections = state.rejections()
    spikes, listing = spike_warnings(fit.ctx, rejections, [a.cand.kind for a in accepted
                                                           if a.cand.kind in ("outliers", "glitches")])
    return Result(rec, model, fitted, grid, t, valid, y0, y_after, before, after, accepted, rejections,
                  before.null.n_replicates,
                  baseline, too_short_warnings(model, grid) + lookalike_warnings(accepted, model, grid)
                  + bursts + spikes, named, listing)


def explain_without_model(rec: Recording, options: Options | None = None, progress: Progress | None = None,
                          mapper: Mapper | None = None) -> Result:
    """``explain`` against the baseline fitted from ``rec`` (`fogmon explain` without
    ``--model``). When the whole record's long taus also allow a rate random walk the
    baseline's windows cannot see (``baseline.baseline_models``) and effects named
    against the baseline are refused against the baseline with that walk, the record
    cannot tell the walk's realisation from those drifts: the result against the walk,
    with a ``lookalike`` warning per refused effect naming it (docs/explain.md, "The
    baseline", item 5)."""
    from fogmon.explain.baseline import baseline_models

    def report(stage: str) -> None:
        if progress is not None:
            progress(stage, 0, 0)

    report("fitting a stationary IEEE-952 baseline model to the recording")
    base, walk = baseline_models(rec)
    res = explain(rec, base, options, baseline=True, progress=progress, mapper=mapper)
    if walk is None or not res.accepted:
        return res
    report(f"judging the effects against a rate random walk K {walk.noise.K_dphsh:.4g} deg/h/sqrt(h) too")
    alt = explain(rec, walk, options, baseline=True, progress=progress, mapper=mapper)
    kept = {a.cand.kind for a in alt.accepted}
    drifts = [a for a in res.accepted if a.cand.kind not in kept]
    if not drifts:
        return res
    alt.warnings.extend(walk_lookalike_warnings(drifts, walk, alt.grid))
    return alt


def _fitted_model(model: SensorModel, stoch: SensorModel, accepted: tuple[Accepted, ...]) -> SensorModel:
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
    n_grid = int(rec.grid_index()[-1]) + 1        # the sample grid, gaps included (explain's own test)
    moving, missing = (len(keep) - keep.sum()) / n_grid, 1.0 - len(keep) / n_grid
    what = "the rate minus 3600 x rot_dps" if "rot_dps" in rec.aux else "the rate"
    if keep.sum() < MIN_STATIONARY_SHARE * n_grid:
        raise FogmonError(f"{rec.name}: platform motion over {100 * moving:.0f} % of the record"
                          + (f" and gaps over {100 * missing:.0f} %" if missing >= 0.005 else "") + " ("
                          + ", ".join(f"{m.t_start_s:.2f}..{m.t_end_s:.2f} s" for m in spans[:5])
                          + (f" and {len(spans) - 5} more" if len(spans) > 5 else "")
                          + f"): too little stationary data to explain (it needs "
                            f"{100 * MIN_STATIONARY_SHARE:.0f} % of the sample grid); fogmon replay shows it, "
                            "--keep-motion analyses it as recorded")
    warnings = [{"kind": "platform_motion", "t_start_s": m.t_start_s, "t_end_s": m.t_end_s,
                 "text": f"{what} moves up to {m.peak_dph:.4g} deg/h from its reference, far beyond the sensor's "
                         f"noise, with no rot_dps to say why (a turntable, a vehicle, a person, the ground): "
                         f"kept out of the analysis (docs/motion.md)"} for m in spans]
    trimmed = Recording(rec.t_s[keep], rec.rate_dph[keep], {k: v[keep] for k, v in rec.aux.items()},
                        dict(rec.meta), rec.path, rec.skipped_rows)
    return trimmed, warnings
