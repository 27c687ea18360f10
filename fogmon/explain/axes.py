"""`fogmon explain` of a recording with several axes (docs/explain.md, "Several axes"):
each axis explained on its own by the one-axis explainer against its own model
(``axis_models``), then ``common``: the aux-driven effects found on several axes with
the same aux channel, each with the cross-axis coherence of the data as evidence
(``coherence``), significant or not.

Coherence, measured on the residuals against the original model (before any fitted
effect, so nothing fitted is fed back as evidence), pair by pair of axes:
- white-level effects (vibration_noise, temperature_noise): correlation between the
  axes of the white level per segment (the Allan deviation at tau0 of the residual in
  SEGMENTS_N segments of the record);
- mean-type effects (thermal_drift, scale_factor): correlation between the axes of the
  non-overlapping Allan differences (difference of consecutive tau-means) of the
  residual at each octave tau of the axes' mismatch regions (every octave tau when
  none of those has MIN_TERMS_N differences), the most significant tau reported,
  Bonferroni over the taus tested.
Both series are autocorrelated when a slow aux channel drives them, so significance
uses Bartlett's effective sample size n / (1 + 2 sum_k rho_a(k) rho_b(k)) in Fisher's z
test of the correlation (two-sided: opposite-sign coefficients are a common cause too).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import norm

from fogmon.errors import FogmonError
from fogmon.explain import mismatch
from fogmon.explain.bootstrap import Mapper, Progress
from fogmon.explain.explainer import Result, check_inputs, explain, explain_without_model, without_motion
from fogmon.explain.options import Options
from fogmon.formats.recording import Recording
from fogmon.sim.features import Feature, other_axis, parse_feature
from fogmon.sim.model import EFFECT_KINDS, Effect, SensorModel, validate_model

#: segments of the record for the per-segment white levels
SEGMENTS_N = 200
#: fewest non-overlapping Allan differences a tau needs to be tested for coherence
MIN_TERMS_N = 20


@dataclass(frozen=True)
class Coherence:
    """Correlation ``r`` between two axes of one measure at ``tau_s`` (s) over
    ``terms_n`` terms, Bartlett's effective sample size ``n_eff`` and the two-sided
    ``p_value`` (Bonferroni over ``taus_n`` taus tested)."""

    axes: tuple[str, str]
    tau_s: float
    r: float
    terms_n: int
    n_eff: float
    p_value: float
    taus_n: int = 1

    def as_json(self, alpha: float) -> dict:
        return {"axes": list(self.axes), "tau_s": self.tau_s, "r": round(self.r, 4), "terms_n": self.terms_n,
                "n_eff": round(self.n_eff, 1), "p_value": float(f"{self.p_value:.3g}"), "taus_tested_n": self.taus_n,
                "significant": self.p_value < alpha}


@dataclass
class Common:
    """An effect ``kind`` found on ``axes`` (two or more) driven by the same aux
    ``channel`` (the recording's column), with the cross-axis coherence of ``measure``
    pair by pair."""

    kind: str
    channel: str
    axes: tuple[str, ...]
    measure: str
    pairs: list[Coherence]
    alpha: float
    #: an ``aux_response`` law's feature (on the recording's columns), "" for other kinds
    feature: str = ""

    @property
    def significant(self) -> bool:
        """Every pair coheres beyond chance at ``alpha``."""
        return bool(self.pairs) and all(c.p_value < self.alpha for c in self.pairs)

    def evidence(self) -> str:
        """One paragraph: the coherence found, and whether it is beyond chance."""
        pairs = "; ".join(f"{c.axes[0]}-{c.axes[1]} r = {c.r:+.3f} at tau {c.tau_s:.4g} s "
                          f"(p = {c.p_value:.2g}, effective n {c.n_eff:.0f} of {c.terms_n})" for c in self.pairs)
        what = f"{self.kind} ({self.feature})" if self.feature else self.kind
        head = (f"{what} found on axes {', '.join(self.axes)}, each driven by the aux channel {self.channel}. "
                f"Cross-axis coherence of {self.measure}: {pairs or 'no pair with enough data to test'}.")
        weak = [f"{c.axes[0]}-{c.axes[1]}" for c in self.pairs if not c.p_value < self.alpha]
        if self.significant:
            return (f"{head} Significant at the {100 * self.alpha:g} % level on every pair: the axes respond "
                    f"together, one cause ({self.channel}) acting on all of them.")
        return (f"{head} Not significant at the {100 * self.alpha:g} % level on {', '.join(weak) or 'any pair'}: "
                f"the data do not show a common response beyond chance there; the axes share the channel, and "
                f"each axis's effect stands on its own evidence (its report).")

    def as_json(self, results: dict[str, Result]) -> dict:
        return {"kind": self.kind, "aux_channel": self.channel, **({"feature": self.feature} if self.feature else {}),
                "axes": list(self.axes),
                "params": {a: _params(results[a], self.kind) for a in self.axes}, "measure": self.measure,
                "coherence": [c.as_json(self.alpha) for c in self.pairs], "significant": self.significant,
                "alpha": self.alpha, "evidence": self.evidence()}


@dataclass
class AxesResult:
    """The explain of every axis of ``recording`` (``results``, by axis, in the
    recording's order; an axis the model lacks is left out with a warning), ``common``
    causes, ``warnings`` (model_axis_missing) and the multi-axis ``fitted`` model."""

    recording: Recording
    model: SensorModel
    results: dict[str, Result]
    common: list[Common]
    fitted: SensorModel
    warnings: list[dict] = field(default_factory=list)
    baseline: bool = False

    @property
    def score_before(self) -> float:
        """The axes' scores combined by the score's own smooth maximum (docs/explain.md)."""
        return mismatch.smooth_max([r.before.score.value for r in self.results.values()])

    @property
    def score_after(self) -> float:
        return mismatch.smooth_max([r.after.score.value for r in self.results.values()])


# ---------------------------------------------------------------- models per axis
def axis_models(rec: Recording, model: SensorModel) -> tuple[dict[str, SensorModel], list[dict]]:
    """The one-axis model of every axis of ``rec`` (``SensorModel.for_axis``; a model
    without [noise.<axis>] tables is the same model on every axis) and a
    ``model_axis_missing`` warning for each axis the model's tables lack: that axis is
    not explained (its [noise] defaults need not hold every term, so explaining against
    them could invent mismatches). FogmonError when the model has none of the axes."""
    t0, t1 = (float(rec.t_s[0]), float(rec.t_s[-1]) + 1.0 / rec.sample_rate_hz) if len(rec) else (0.0, 0.0)
    models, warnings = {}, []
    for a in rec.axis_names():
        if model.axes and a not in model.axes:
            warnings.append({"kind": "model_axis_missing", "t_start_s": t0, "t_end_s": t1,
                             "text": f"the model has no [noise.{a}] table (its axes: {', '.join(model.axes)}): "
                                     f"axis {a} is not explained (skipped); add a [noise.{a}] table to explain it"})
            continue
        models[a] = model.for_axis(a)
    if not models:
        raise FogmonError(f"{rec.name}: the model has [noise.<axis>] tables for axes {', '.join(model.axes)} only, "
                          f"none of the recording's axes ({', '.join(rec.axes)})")
    return models, warnings


def one_axis_model(model: SensorModel, rec: Recording, axis: str | None = None) -> SensorModel:
    """The model a one-axis recording is explained against: ``model`` itself when it has
    no axis tables, else its axis ``axis`` (default: the recording's ``meta['axis']``,
    set when an axis was picked from a multi-axis source); FogmonError when neither names
    one of the model's axes."""
    if not model.axes:
        return model
    name = axis or rec.meta.get("axis")
    if name not in model.axes:
        raise FogmonError(f"{rec.name}: one axis{f' ({name})' if name else ''}, but the model has [noise.<axis>] "
                          f"tables for axes {', '.join(model.axes)}: pick one with `axis` NAME")
    return model.for_axis(name)


# ---------------------------------------------------------------- explain
def explain_axes(rec: Recording, model: SensorModel | None, options: Options | None = None,
                 keep_motion: bool = False, progress: Progress | None = None,
                 mapper: Mapper | None = None, where: str = "model") -> AxesResult:
    """Explain every axis of the multi-axis ``rec`` against its model (``axis_models``;
    ``model`` None: a stationary baseline fitted from each axis), platform motion kept
    out of each axis unless ``keep_motion``; then the common causes (``common_causes``)
    and the fitted multi-axis model (``fitted_model``). Every axis's inputs are checked
    before any work (``check_inputs``, ``where`` naming the model, e.g. its file). Stages
    go to ``progress`` prefixed with the axis; bootstrap replicates run by ``mapper``
    (explain)."""
    from fogmon.explain.report import record_fit

    opt = options or Options()
    report = progress or (lambda stage, done, total: None)
    if model is not None:
        model = validate_model(model)
        models, warnings = axis_models(rec, model)
        axes = list(models)
        for a in axes:
            check_inputs(with_other_rates(rec, a), models[a], opt.window_s, where=where)
    else:
        axes, warnings = list(rec.axis_names()), []
    results: dict[str, Result] = {}
    for a in axes:
        def axis_progress(stage: str, done: int = 0, total: int = 0, a: str = a) -> None:
            report(f"axis {a}: {stage}", done, total)

        one = as_recorded = with_other_rates(rec, a)
        motion: list[dict] = []
        if not keep_motion:
            axis_progress("looking for platform motion")
            one, motion = without_motion(one)
        res = (explain_without_model(one, opt, axis_progress, mapper) if model is None
               else explain(one, models[a], opt, progress=axis_progress, mapper=mapper))
        res.warnings[:0] = motion
        res.record_fit = record_fit(as_recorded, keep_motion)
        results[a] = res
    common = common_causes(rec, results, opt.alpha)
    base = model if model is not None else SensorModel(rec.sample_rate_hz, 0.0, results[axes[0]].model.noise, [])
    return AxesResult(rec, base, results, common, fitted_model(base, results), warnings, model is None)


def with_other_rates(rec: Recording, axis: str) -> Recording:
    """The one-axis recording of ``axis`` with every other axis's rate as an aux column
    ``rate_<other>_dph`` (deg/h, the measured rate): the features of a cross-coupling law
    (``aux_response``, fogmon.sim.features)."""
    one = rec.for_axis(axis)
    others = {f"rate_{b}_dph": rec.rate_dph[:, j] for j, b in enumerate(rec.axes) if b != axis}
    return replace(one, aux={**one.aux, **others})


def fitted_model(model: SensorModel, results: dict[str, Result]) -> SensorModel:
    """The multi-axis model with every axis's fit: a [noise.<axis>] table per explained
    axis (its fitted coefficients), the model's own effects as they were, and each
    axis's fitted effects with ``axes = [axis]``. A fitted bias (the baseline's) that
    differs from the model's [sensor] bias_dph is a ``bias_step`` at the record's start
    on that axis (the model format has one bias for all axes)."""
    effects = list(model.effects)
    for a, res in results.items():
        own = len(res.model.effects)
        effects += [replace(e, axes=(a,)) for e in res.fitted.effects[own:]]
        if res.fitted.bias_dph != model.bias_dph:
            effects.append(Effect("bias_step", {"t_s": float(res.t_s[0]),
                                                "step_dph": res.fitted.bias_dph - model.bias_dph}, (a,)))
    axis_noise = {**model.axis_noise, **{a: res.fitted.noise for a, res in results.items()}}
    return validate_model(SensorModel(model.sample_rate_hz, model.bias_dph, model.noise, effects,
                                      dict(model.meta), axis_noise))


def _params(res: Result, kind: str) -> dict:
    return next(dict(a.cand.params) for a in res.accepted if a.cand.kind == kind)


# ---------------------------------------------------------------- common causes
def channel_of(rec: Recording, axis: str, channel: str) -> str:
    """The recording's column that is ``channel`` for ``axis``: its own ``<channel>_<axis>``
    when present, else the shared one (fogmon.block.axis_aux)."""
    own = f"{channel}_{axis}"
    return own if own in rec.aux else channel


def common_causes(rec: Recording, results: dict[str, Result], alpha: float) -> list[Common]:
    """Aux-driven effect kinds accepted on two or more axes with the same aux column (an
    ``aux_response`` law: per term, the same feature of the same aux columns; a term on
    another axis's rate is no common cause), with the cross-axis coherence of the data
    (module docstring), in the order of the axes' effects."""
    groups: dict[tuple[str, str, str], list[str]] = {}
    for a, res in results.items():
        for acc in res.accepted:
            for channel, feature in _causes(rec, a, acc.cand.kind, acc.cand.params):
                axes = groups.setdefault((acc.cand.kind, channel, feature), [])
                if a not in axes:
                    axes.append(a)
    out = []
    for (kind, channel, feature), axes in groups.items():
        if len(axes) < 2:
            continue
        white = EFFECT_KINDS[kind].nature == "white_level"
        pairs = [pair_coherence(rec, results, a, b, white) for i, a in enumerate(axes) for b in axes[i + 1:]]
        seg_s = segment_n(int(rec.grid_index()[-1]) + 1) / rec.sample_rate_hz
        measure = (f"the white level (Allan deviation at tau0 of the residual per {seg_s:.4g} s segment)"
                   if white else "the residual's non-overlapping Allan differences at the mismatch taus")
        out.append(Common(kind, channel, tuple(axes), measure, [p for p in pairs if p is not None], alpha, feature))
    return out


def _causes(rec: Recording, axis: str, kind: str, params: dict) -> list[tuple[str, str]]:
    """(the recording's aux column(s), feature) an accepted effect of ``axis`` is driven by:
    its kind's aux channel; each term of an ``aux_response`` that reads aux columns only
    (its feature rewritten on the recording's columns); none for other kinds."""
    if kind != "aux_response":
        need = EFFECT_KINDS[kind].aux
        return [(channel_of(rec, axis, need), "")] if need is not None else []
    out = []
    for t in params["terms"]:
        f = parse_feature(t["feature"])
        if any(other_axis(n) is not None for n in f.names):
            continue
        cols = tuple(channel_of(rec, axis, n) for n in f.names)
        out.append((", ".join(dict.fromkeys(cols)), Feature(f.shape, cols).text))
    return out


def on_recording_grid(rec: Recording, res: Result) -> np.ndarray:
    """An axis's residual against the original model (deg/h) on the whole recording's
    sample grid, NaN where that axis has no valid sample (gaps, platform motion)."""
    n = int(rec.grid_index()[-1]) + 1
    out = np.full(n, np.nan)
    start = int(round((float(res.t_s[0]) - float(rec.t_s[0])) * rec.sample_rate_hz))
    y = np.where(res.valid, res.residual_before, np.nan)
    out[start:start + len(y)] = y[: n - start]
    return out


def segment_n(n: int) -> int:
    """Samples per segment of the white levels of an ``n``-sample record (SEGMENTS_N of
    them, at least 16 samples each)."""
    return max(16, n // SEGMENTS_N)


def segment_adev0(y: np.ndarray, seg: int) -> np.ndarray:
    """The Allan deviation at tau0 (deg/h) of ``y`` (deg/h, NaN = missing) in each
    segment of ``seg`` samples, NaN where a segment has fewer than half its differences."""
    d = np.diff(y)
    k = len(d) // seg
    d = d[: k * seg].reshape(k, seg)
    ok = np.isfinite(d)
    with np.errstate(invalid="ignore", divide="ignore"):
        avar = np.where(ok, d, 0.0) ** 2 @ np.ones(seg) / ok.sum(axis=1) / 2.0
    return np.where(ok.sum(axis=1) >= seg / 2, np.sqrt(avar), np.nan)


def allan_differences(y: np.ndarray, m: int) -> np.ndarray:
    """Non-overlapping Allan differences at tau = m samples: mean of block k+1 minus mean
    of block k over consecutive blocks of ``m`` samples of ``y`` (NaN when a block has a
    missing sample)."""
    k = len(y) // m
    means = y[: k * m].reshape(k, m).mean(axis=1)
    return np.diff(means)


def correlation_test(x: np.ndarray, y: np.ndarray) -> tuple[float, int, float, float] | None:
    """(Pearson r, terms used, Bartlett effective n, two-sided p) of the pairs where both
    are finite; None with fewer than MIN_TERMS_N of them. The series' own
    autocorrelations rho (up to lag n/4) shrink n to n / (1 + 2 sum rho_x rho_y)
    (clipped to 3..n); p from Fisher's z with that n."""
    ok = np.isfinite(x) & np.isfinite(y)
    n = int(ok.sum())
    if n < MIN_TERMS_N:
        return None
    xa, ya = x[ok] - x[ok].mean(), y[ok] - y[ok].mean()
    sx, sy = math.sqrt(float(xa @ xa)), math.sqrt(float(ya @ ya))
    if sx == 0 or sy == 0:
        return None
    r = float(xa @ ya) / (sx * sy)
    lags = max(1, n // 4)
    n_eff = float(np.clip(n / (1.0 + 2.0 * float(_acf(xa, lags) @ _acf(ya, lags))), 3.0, n))
    z = math.atanh(min(abs(r), 1 - 1e-15)) * math.sqrt(max(n_eff - 3.0, 1.0))
    return r, n, n_eff, float(2.0 * norm.sf(z))


def _acf(x: np.ndarray, lags: int) -> np.ndarray:
    """Sample autocorrelation of the centred series ``x`` at lags 1..``lags`` (FFT)."""
    f = np.fft.rfft(x, 2 * len(x))
    ac = np.fft.irfft(f * np.conj(f))[: lags + 1]
    return ac[1:] / ac[0]


def _mismatch_taus_n(res: Result) -> set[int]:
    """Octave taus (samples) inside the tau band of any of the axis's mismatch regions."""
    g = res.grid
    m_all = np.union1d(g.m, g.m_whole)
    out: set[int] = set()
    for r in res.before.regions:
        lo, hi = r.tau_min_s * g.sample_rate_hz, r.tau_max_s * g.sample_rate_hz
        out |= {int(m) for m in m_all if lo * (1 - 1e-9) <= m <= hi * (1 + 1e-9)}
    return out


def pair_coherence(rec: Recording, results: dict[str, Result], a: str, b: str, white: bool) -> Coherence | None:
    """The coherence of axes ``a`` and ``b`` (module docstring): white levels per segment
    (``white``) or Allan differences at the axes' mismatch taus, the most significant tau
    reported with its p Bonferroni-corrected over the taus tested; None when no tau has
    MIN_TERMS_N terms on both axes."""
    ya, yb = on_recording_grid(rec, results[a]), on_recording_grid(rec, results[b])
    sample_rate_hz = rec.sample_rate_hz
    if white:
        seg = segment_n(len(ya))
        t = correlation_test(segment_adev0(ya, seg), segment_adev0(yb, seg))
        return None if t is None else Coherence((a, b), 1.0 / sample_rate_hz, t[0], t[1], t[2], t[3])
    taus = _mismatch_taus_n(results[a]) | _mismatch_taus_n(results[b])
    n = len(ya)
    usable = sorted(m for m in taus if n // m - 1 >= MIN_TERMS_N)
    if not usable:
        m = 1
        usable = []
        while n // m - 1 >= MIN_TERMS_N:
            usable.append(m)
            m *= 2
    tests = [(m, correlation_test(allan_differences(ya, m), allan_differences(yb, m))) for m in usable]
    found = [(m, t) for m, t in tests if t is not None]
    if not found:
        return None
    m, (r, terms, n_eff, p) = min(found, key=lambda mt: mt[1][3])
    return Coherence((a, b), m / sample_rate_hz, r, terms, n_eff, min(1.0, p * len(found)), len(found))
