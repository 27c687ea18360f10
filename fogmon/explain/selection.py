"""Forward selection of candidate physics (docs/explain.md): the frozen ``Selection``
state - the current fit, the effects accepted, the kinds refused, contradicted or
deferred, this round's candidates still to judge - whose ``step`` judges the next
candidate (BIC, held-out check, the map's verdict, the score) and returns the next
state; ``explain`` steps until the state is ``done``."""
from __future__ import annotations

from collections.abc import Mapping, Set as AbstractSet
from dataclasses import dataclass, field, fields, replace
from typing import Literal

import numpy as np

from fogmon.explain import lookalike, mismatch
from fogmon.explain.analysis import Analysis, analyse, rescored, whittle_context
from fogmon.explain.bootstrap import Mapper, Progress, bootstrap, extended, settled
from fogmon.explain.candidates import CANDIDATES, Candidate, Context
from fogmon.explain.candidates.base import EXACT_LAW, LONG_MEMORY, centred, flicker_psd
from fogmon.explain.fitting import Whittle
from fogmon.explain.options import MAX_GROWTH, SETTLE_SE
from fogmon.explain.replicas import Replicas
from fogmon.explain.scan_null import calibrated_kinds
from fogmon.sim.model import SensorModel

#: how many times a kind may be added (several spectral lines are common)
MAX_PER_KIND = {"periodic": 4, "bias_step": 2, "vibration_lines": 2}
#: kinds not tried against the baseline (no --model): its coefficients are the
#: recording's own, so a corrected [noise] would not be a finding
BASELINE_EXCLUDED = ("noise",)


@dataclass
class Accepted:
    """An accepted effect with its selection statistics and per-effect scores."""

    cand: Candidate
    bic_gain: float
    heldout: str
    score_before: float
    score_after: float


@dataclass(frozen=True, eq=False)
class Fit:
    """The residual against the model with the effects accepted so far, and what judges
    it: the stochastic model ``stoch``, its bootstrap ``null``, the candidates' context
    ``ctx`` (which holds the residual, ``y``), the candidates ``cands`` fitted to it
    (best BIC first, ``candidates``) and the map's ``analysis``."""

    stoch: SensorModel
    null: mismatch.Null
    ctx: Context
    cands: list[Candidate]
    analysis: Analysis

    @property
    def y(self) -> np.ndarray:
        """The residual (deg/h, 0 where invalid; a new array, ``Context.residual``)."""
        return self.ctx.residual()


@dataclass(frozen=True, eq=False)
class Setting:
    """What stays fixed while effects are selected: the sample grid's times ``t_s`` (s),
    gap-filled ``aux`` channels and ``valid`` mask (the bootstraps' replicates are drawn
    on them); the map ``grid``; the bootstrap's ``n_boot`` replicates, ``seed``,
    family-wise ``alpha``, ``workers`` and ``mapper`` (bootstrap.Mapper); the effect
    budget ``max_effects``; where ``progress`` goes."""

    t_s: np.ndarray
    aux: dict
    valid: np.ndarray
    grid: mismatch.Grid
    n_boot: int
    seed: int
    alpha: float
    workers: int
    max_effects: int
    progress: Progress | None = None
    mapper: Mapper | None = None
    #: the recording's metadata (units of its aux channels)
    meta: Mapping[str, str] = field(default_factory=dict)

    def fit(self, y: np.ndarray, stoch: SensorModel, null: mismatch.Null, counts: Mapping[str, int],
            contradicted: AbstractSet[str]) -> Fit:
        """The residual ``y`` (deg/h, 0 where invalid; taken over by the context, which
        writes into it) judged against ``stoch`` and its ``null``: the context, the
        candidates (``counts``: kind -> times added) and the analysis (the tests of the
        ``contradicted`` kinds not counted in its score)."""
        ctx = whittle_context(stoch, self.aux, self.t_s, self.valid, y, copy=False)
        del y
        ctx.meta = dict(self.meta)
        ctx.cache[LONG_MEMORY] = bool(calibrated_kinds(stoch, float(self.t_s[-1] - self.t_s[0])))
        maps = mismatch.log_avar(ctx.residual(np.nan), ctx.valid, self.grid)
        null, cands = self.settled(stoch, null, maps, ctx, counts)
        fit = Fit(stoch, null, ctx, cands, analyse(ctx, null, self.grid, cands, contradicted, maps))
        # record-length arrays, computed again if needed (memory)
        for key in ("spike_scan", "spikes", "model_psd", EXACT_LAW):
            ctx.cache.pop(key, None)
        return fit


    def settled(self, stoch: SensorModel, null: mismatch.Null, maps: tuple[np.ndarray, np.ndarray], ctx: Context,
                counts: Mapping[str, int]) -> tuple[mismatch.Null, list[Candidate]]:
        """The sequential Monte Carlo test (bootstrap.settled): ``null`` (of ``stoch``)
        with more replicates while the map's family-wise test (of the residual's ln avar
        ``maps``, mismatch.undecided) or a candidate's pass at its chance bar (``bars_undecided``) lie within its Monte
        Carlo error; and the candidates fitted in ``ctx`` against the null's bars. The
        grown null is kept by the fit (a mean-type effect's trial reuses it)."""
        def more(nl: mismatch.Null) -> mismatch.Null:
            if self.progress:
                self.progress(f"bootstrap null undecided at {nl.n_replicates} simulations: "
                              f"{self.n_boot} more", 0, 0)
            return extended(nl, Replicas(stoch, self.t_s, self.aux, self.valid), self.grid, self.n_boot,
                            self.workers, self.progress, self.mapper)

        def map_undecided(nl: mismatch.Null) -> bool:
            return mismatch.undecided(*mismatch.zscores(*maps, nl), nl, SETTLE_SE)

        null = settled(null, map_undecided, more, self.n_boot)
        cands = candidates(ctx, counts, null.scan_bars)
        while null.n_replicates < MAX_GROWTH * self.n_boot and bars_undecided(cands, null, ctx.penalty):
            null = settled(more(null), map_undecided, more, self.n_boot)
            cands = candidates(ctx, counts, null.scan_bars)
        return null, cands


def bars_undecided(cands: list[Candidate], null: mismatch.Null, penalty: float) -> bool:
    """Whether a candidate's gain lies above the chance bar the null's replicates set for
    its kind (scan_null) by less than ``SETTLE_SE`` Monte Carlo standard errors while no
    other bar of it (BIC's, its own search's) decides alone: a pass that more replicates
    could refuse (a refusal is not confirmed: it names nothing)."""
    for c in cands:
        bar = null.scan_bars.get(c.kind)
        if bar is None:
            continue
        bar = c.search_bar + bar  # the null's bar is an excess over the search's own (scan_null)
        band = SETTLE_SE * null.scan_bar_se[c.kind]
        if bar <= c.gain < bar + band and c.bic_bar(penalty) < c.gain and c.search_bar < bar + band:
            return True
    return False


@dataclass(frozen=True, eq=False)
class Verdict:
    """What the search does with one candidate (``Selection.judge``): ``action`` "stop"
    (its BIC gain is not positive: the rest of its tier is no better), "defer" (retried
    after the next acceptance), "reject" (for good), "contradicted" (for good: added, it
    opens a whole-record deficit in the map) or "accept"; its ``bic_gain``, ``why`` (for
    an accepted one its held-out note) and, accepted, the ``trial`` fit with it added."""

    action: Literal["stop", "defer", "reject", "contradicted", "accept"]
    bic_gain: float
    why: str = ""
    trial: Fit | None = None


@dataclass(frozen=True, eq=False)
class Selection:
    """The state of the forward selection: the current ``fit`` (against the model with
    the ``accepted`` effects; ``counts``: kind -> times added), the ``rejected``
    candidates (kind, BIC gain, why) with the kinds ``refused`` for good (those of them
    the map ``contradicted`` no longer count in the score's tests), the kinds
    ``deferred`` until the next acceptance (kind -> (BIC gain, why)), and ``pending``:
    this round's candidates still to judge, tier by tier (``tiers``)."""

    setting: Setting
    fit: Fit
    counts: Mapping[str, int]
    accepted: tuple[Accepted, ...] = ()
    rejected: tuple[tuple[str, float, str], ...] = ()
    refused: frozenset[str] = frozenset()
    contradicted: frozenset[str] = frozenset()
    deferred: Mapping[str, tuple[float, str]] = field(default_factory=dict)
    pending: tuple[tuple[Candidate, ...], ...] = ()

    @classmethod
    def start(cls, setting: Setting, y: np.ndarray, stoch: SensorModel, null: mismatch.Null,
              baseline: bool) -> Selection:
        """The state before any effect: residual ``y`` (deg/h) against ``stoch`` and its
        ``null`` (``baseline``: the model was fitted from the recording, BASELINE_EXCLUDED)."""
        counts = {k: MAX_PER_KIND.get(k, 1) for k in BASELINE_EXCLUDED} if baseline else {}
        fit = setting.fit(y, stoch, null, counts, frozenset())
        return cls(setting, fit, counts, pending=_pending(fit.cands, frozenset(), fit.ctx.penalty))

    @property
    def done(self) -> bool:
        """No candidate left to judge in this round, or the effect budget spent."""
        return not self.pending or len(self.accepted) >= self.setting.max_effects

    def step(self) -> Selection:
        """The state after judging the next pending candidate (``judge``): its tier
        ended (stop), it deferred, rejected or contradicted (the score's tests then
        taken again without it), or it accepted (a new round on the trial's fit)."""
        c = self.pending[0][0]
        if isinstance(c, _Light) and c.bic_gain(self.fit.ctx.penalty) > 0:
            c = fitted(c.kind, self.fit.ctx, self.fit.null.scan_bars) or c  # its arrays were let go: fit again
        v = self.judge(c)
        if v.action == "stop":
            return replace(self, pending=self.pending[1:])
        tier = self.pending[0][1:]
        rest = ((tier,) if tier else ()) + self.pending[1:]
        if v.action == "defer":
            return replace(self, deferred={**self.deferred, c.kind: (v.bic_gain, v.why)}, pending=rest)
        if v.action in ("reject", "contradicted"):
            out = replace(self, rejected=(*self.rejected, (c.kind, v.bic_gain, v.why)),
                          refused=self.refused | {c.kind}, pending=rest)
            if v.action == "reject":
                return out
            contradicted = self.contradicted | {c.kind}
            f = self.fit
            return replace(out, contradicted=contradicted,
                           fit=replace(f, analysis=rescored(f.analysis, f.cands, f.ctx.penalty, contradicted)))
        assert v.trial is not None  # an accepted candidate comes with its trial
        c = lookalike.explained(c, self.fit.cands, v.trial.cands, self.fit.ctx.penalty)
        before, after = self.fit.analysis.score.value, v.trial.analysis.score.value
        # what the report and the fitted model read of it: its design and held-out closure let go (memory)
        accepted = (*self.accepted, Accepted(replace(c, design=None, heldout=None), v.bic_gain, v.why, before, after))
        if self.setting.progress:
            self.setting.progress(f"effect {len(accepted)}: {c.kind} (score {before:.3g} -> {after:.3g})", 0, 0)
        pending = _pending(v.trial.cands, self.refused, v.trial.ctx.penalty)
        return replace(self, fit=v.trial, counts={**self.counts, c.kind: self.counts.get(c.kind, 0) + 1},
                       accepted=accepted, deferred={}, pending=pending)

    def judge(self, c: Candidate) -> Verdict:
        """What the search does with candidate ``c`` of the current round: stop when its
        BIC gain is not positive; defer a periodic term inside a resolved vibration line;
        reject one failing the held-out check; then try it (``trial``): contradicted
        when the map shows a new whole-record deficit (not for effects with an estimate:
        subtracted ones, and vibration lines, whose band-pass shape may leave a deficit
        elsewhere; guarded, real sway lines were refused, docs/explain.md, limits),
        deferred when it does not lower the score, else accepted."""
        ctx, current = self.fit.ctx, self.fit.analysis
        bg = c.bic_gain(ctx.penalty)
        if bg <= 0:
            return Verdict("stop", bg)
        look = lookalike.refusal(c, self.fit.cands, ctx, lambda o: fitted(o.kind, ctx, self.fit.null.scan_bars))
        if look is not None:
            return Verdict("defer", bg, look)
        line = _inside_line(c, self.fit.cands, ctx.sample_rate_hz / ctx.n)
        if line is not None:
            return Verdict("defer", bg, f"its frequency lies inside the narrowband line at {line:.4g} Hz that "
                                        f"vibration_lines fits (random vibration, not one coherent sinusoid)")
        ok, note = _heldout(ctx, c)
        if not ok:
            return Verdict("reject", bg, f"failed the held-out check: {note}")
        # judged: its design and held-out closure are not read again (a look-alike check
        # fits a candidate without them again), so the trial's round is built without them
        # (memory: a periodic design is two record-length columns)
        c.design = c.heldout = None
        trial = self.trial(c)
        after = trial.analysis
        overfit = _new_deficit(current, after) if c.rate is None else None
        if overfit is not None:
            return Verdict("contradicted", bg, f"makes the model noisier than the recording at tau {overfit} s (the "
                                               f"spectral fit trades long taus for short ones; its test no longer "
                                               f"counts in the score)")
        if not _lowers(current.score.value, after.score.value):
            return Verdict("defer", bg, f"does not lower the score ({current.score.value:.3f} -> "
                                        f"{after.score.value:.3f}): what it fits is within chance "
                                        f"next to what is still missing")
        return Verdict("accept", bg, note, trial)

    def trial(self, c: Candidate) -> Fit:
        """The fit with ``c`` added: a mean-type effect, or outliers replaced, is
        subtracted from the residual (``candidates.base.centred``: it stays centred over
        the valid samples; same null); a noise-type one joins the stochastic model (a new
        bootstrap null)."""
        s, f = self.setting, self.fit
        n0 = c.white_n0_dpsh
        if _subtracted(c) and n0 is None:
            stoch, null = f.stoch, f.null
        elif _subtracted(c) and n0 is not None:  # spikes taken out and the white level they inflated refitted
            stoch = _white_refitted(f.stoch, n0)
            if s.progress:
                s.progress(f"bootstrap null with {c.kind} removed and N refitted: {s.n_boot} simulations", 0, 0)
            null = bootstrap(Replicas(stoch, s.t_s, s.aux, s.valid), s.grid, s.n_boot,
                             s.seed + 7919 * (len(self.accepted) + 1), s.alpha, s.workers, s.progress, s.mapper)
        else:
            stoch = _joined(f.stoch, c)
            if s.progress:
                s.progress(f"bootstrap null with {c.kind} added: {s.n_boot} simulations", 0, 0)
            null = bootstrap(Replicas(stoch, s.t_s, s.aux, s.valid), s.grid, s.n_boot,
                             s.seed + 7919 * (len(self.accepted) + 1), s.alpha, s.workers, s.progress, s.mapper)
        y = f.y   # a new array, taken over by the trial's context (which zeroes it where invalid)
        if _subtracted(c) and c.rate is not None:
            y -= centred(c.rate, s.valid)   # the residual stays centred over the valid samples
        return s.fit(y, stoch, null, {**self.counts, c.kind: self.counts.get(c.kind, 0) + 1}, self.contradicted)

    def rejections(self) -> list[tuple[str, float, str]]:
        """Every candidate not accepted, as (kind, BIC gain, why): those rejected or
        contradicted, those deferred when the search ended, and those of its last round
        below the bar."""
        pen = self.fit.ctx.penalty
        return [*self.rejected, *((k, bg, why) for k, (bg, why) in self.deferred.items()),
                *((c.kind, c.bic_gain(pen), _below(c, pen, self.fit.null.scan_bars)) for c in self.fit.cands
                  if c.bic_gain(pen) <= 0 and c.kind not in self.refused)]


def _below(c: Candidate, penalty: float, bars: Mapping[str, float]) -> str:
    """Which bar the candidate ``c`` stayed below."""
    if c.chance_bar > max(c.search_bar, c.bic_bar(penalty)):
        return "below the chance bar of the model's own noise (its rate random walk or flicker, simulated)"
    if c.search_bar <= c.bic_bar(penalty):
        return "below the BIC bar"
    if c.kind == lookalike.LAW:
        return "below the feature search's chance bar"
    return ("below the change-point search's chance bar" if c.kind == "bias_step"
            else "below the frequency search's chance bar")


def candidates(ctx: Context, counts: Mapping[str, int], bars: Mapping[str, float]) -> list[Candidate]:
    """Every applicable candidate (``CANDIDATES``) fitted to the current residual, best
    BIC first but a channel law that passes its bar ahead of all (``lookalike.first``;
    refused kinds included: they still measure what is missing, the score's
    ``tests``, unless the map contradicted them, ``analysis.matched_tests_figure``)."""
    out: list[Candidate] = []
    best: dict[bool, int] = {}  # tier (first or not) -> index in out of its best candidate so far
    for kind in CANDIDATES:
        if counts.get(kind, 0) >= MAX_PER_KIND.get(kind, 1):
            continue
        c = fitted(kind, ctx, bars)
        if c is None:
            continue
        # only each tier's best candidate past its bar keeps its arrays (it is judged first);
        # the others are fitted again if they come to be judged (bounded memory)
        tier, bg = _first_tier(c), c.bic_gain(ctx.penalty)
        j = best.get(tier)
        if bg > 0 and (j is None or bg > out[j].bic_gain(ctx.penalty)):
            if j is not None:
                out[j] = light(out[j])
            best[tier] = len(out)
            out.append(c)
        else:
            out.append(light(c))
    out.sort(key=lambda c: -c.bic_gain(ctx.penalty))
    return lookalike.first(out, ctx.penalty)


def fitted(kind: str, ctx: Context, bars: Mapping[str, float]) -> Candidate | None:
    """Candidate ``kind`` fitted to the context's residual (``CANDIDATES``) with the null's
    chance bar for the kind (``bars``: scan_null, an excess over its own search's bar), if any."""
    c = CANDIDATES[kind](ctx)
    if c is not None and kind in bars:
        c = replace(c, chance_bar=c.search_bar + float(bars[kind]))
    return c


class _Light(Candidate):
    """A candidate without its record-length arrays and closures (``light``)."""


def light(c: Candidate) -> Candidate:
    """``c`` without its arrays and closures (what the score's tests and the report's
    refusals read: kind, parameters, gain, bars), so that it holds no record-length data;
    ``Selection.judge`` fits it again from the registry if it comes to be judged."""
    if isinstance(c, _Light):
        return c
    return _Light(**{**{f.name: getattr(c, f.name) for f in fields(c)},
                     "rate": None, "design": None, "heldout": None, "listing": None, "stoch_base": None})


def _pending(cands: list[Candidate], refused: AbstractSet[str], penalty: float) -> tuple[tuple[Candidate, ...], ...]:
    """A round's candidates to judge, tier by tier (``tiers``; empty tiers left out),
    without the kinds refused for good (each kind is fitted once per round, so nothing
    else needs skipping within it)."""
    kept = (tuple(c for c in tier if c.kind not in refused) for tier in tiers(cands, penalty))
    return tuple(tier for tier in kept if tier)


def _joined(stoch: SensorModel, c: Candidate) -> SensorModel:
    """The stochastic model with the noise-type candidate ``c``: the noise kind's
    corrected coefficients (no new effect), or its effect added to the model it joins
    (``stoch_base``, with a white-level effect's N0)."""
    if c.corrected_noise is not None:
        return SensorModel(stoch.sample_rate_hz, 0.0, c.corrected_noise, stoch.effects)
    base = stoch if c.stoch_base is None else c.stoch_base
    noise = base.noise if c.white_n0_dpsh is None else replace(base.noise, N_dpsh=c.white_n0_dpsh)
    return SensorModel(stoch.sample_rate_hz, 0.0, noise, [*base.effects, c.effect()])


def _white_refitted(stoch: SensorModel, n0: float) -> SensorModel:
    """``stoch`` with its white level N0 = ``n0`` (deg/sqrt(h))."""
    return SensorModel(stoch.sample_rate_hz, 0.0, replace(stoch.noise, N_dpsh=n0), stoch.effects)


def tiers(cands: list[Candidate], penalty: float) -> list[list[Candidate]]:
    """Selection order: effects tied to time structure or an aux channel (mean-type,
    white-level) first; the broad spectral noise terms (markov, bandwidth) only when
    none of those passes - a spectral term can always soak up part of a deterministic
    signal's power, never the other way round. Corrected IEEE-952 coefficients (the
    ``noise`` kind) are judged in the first tier, but behind every physical candidate
    there that passes its bar (BIC gain > 0 with ``penalty``, the tier being judged
    best gain first): a white-level effect, when an aux channel co-varies with the
    white level; a mean-type effect, whose test is calibrated to the recording's noise
    level and judged against its residual's own slow noise (a wrong B or N cannot fake
    it, docs/explain.md item 5), while the corrected coefficients' Allan fit counts a
    settling, a drift or a step as noise. Once the physical effect is in, the
    correction is judged on what is left. A Gauss-Markov term with the larger BIC gain
    (``penalty``: ln n) takes the noise kind's place, just before it
    (``lookalike.ahead``)."""
    first = [c for c in cands if _first_tier(c)]
    coef = [c for c in first if c.nature == "coefficients"]
    physical = [c for c in first if c.nature != "coefficients" and c.bic_gain(penalty) > 0]
    if coef and physical:  # the coefficient correction moves behind the last of them
        first = [c for c in first if c.nature != "coefficients"]
        at = first.index(physical[-1]) + 1
        first[at:at] = coef
    return list(lookalike.ahead(first, [c for c in cands if c not in first], penalty))


def _first_tier(c: Candidate) -> bool:
    """Whether ``c`` is judged in the first tier (``tiers``): tied to time structure or an
    aux channel, or the model's own coefficients."""
    return c.nature in ("mean", "white_level", "coefficients") or _subtracted(c)


def _heldout_mean(ctx: Context, X: np.ndarray, S: np.ndarray) -> tuple[bool, str]:
    """Fit on one half of the record, predict the other, both against the noise PSD
    ``S`` that judged the effect on the whole record (``judged_psd``): wherever the
    half-fit is itself significant (chi2 gain > 9) and predicts a visible effect in the
    other half (expected chi2 > 9), the other half's chi-square must drop. A design
    column the fitting half does not hold (``_determined``: a thermal branch of falling
    temperature in a half where it only rises) predicts nothing there: it is fitted
    freely in the other half, as its mean is. Each half's arrays are let go before the
    next are made (memory: a few record-length arrays per design column)."""
    half = np.arange(ctx.n) < ctx.n // 2
    notes = []
    ok = True
    for fit_m, test_m, name in ((half, ~half, "second"), (~half, half, "first")):
        got = _half_fit(ctx, X, fit_m, S)
        if got is None:
            notes.append(f"{name} half: n/a (not determined by the other half)")
            continue
        expected, g = _half_test(ctx, X, test_m, *got, S)
        if g is None:
            notes.append(f"{name} half: n/a (effect not visible there)")
            continue
        notes.append(f"{name} half: chi2 drop {g:.1f} (expected {expected:.1f})")
        ok &= g > 0
    return ok, "; ".join(notes)


def _centred(ctx: Context, X: np.ndarray, w: Whittle, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """DFTs (``w``: the Whittle GLS of the half, its valid samples ``v``) of the residual and
    of the design's columns on the half, each less its mean there (the bias is free in
    each half) and 0 elsewhere, and each column's energy about that mean there; a column
    at a time, each straight into its column of the result (memory: no centred or masked
    copy of the design)."""
    Yf = w.fft(np.where(v, ctx.y - ctx.y[v].mean(), 0.0))
    XF = np.empty((ctx.n // 2 + 1, X.shape[1]), dtype=np.complex128)
    energy = np.empty(X.shape[1])
    for j in range(X.shape[1]):
        col = X[:, j] - X[v, j].mean()
        col[~v] = 0.0   # as w.fft masks it
        if not np.isfinite(col).all():
            np.nan_to_num(col, copy=False)
        energy[j] = np.dot(col, col)
        np.fft.rfft(col, out=XF[:, j])
    return Yf, XF, energy


#: a design column holds less than this share of its energy (about its mean, over the
#: whole record) in a half: that half does not determine its coefficient
DETERMINED_SHARE = 1e-6


def _determined(ctx: Context, X: np.ndarray, energy: np.ndarray) -> np.ndarray:
    """Which columns of ``X`` a half determines (``energy``: each column's about its mean there)."""
    whole = np.array([np.var(X[ctx.valid, j]) * ctx.valid.sum() for j in range(X.shape[1])])
    return energy > DETERMINED_SHARE * whole


def _half(ctx: Context, m: np.ndarray, S: np.ndarray) -> tuple[Whittle, np.ndarray]:
    """The Whittle GLS of the half ``m`` against the noise PSD ``S`` and its valid samples."""
    v = ctx.valid & m
    return Whittle(S, ctx.n, v), v


def _half_fit(ctx: Context, X: np.ndarray, m: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """GLS coefficients of the columns of design ``X`` that the half ``m`` determines
    (``_determined``), fitted there against the noise PSD ``S``, and which those are;
    None when none is or that fit is not itself significant (chi2 gain < 9)."""
    w, v = _half(ctx, m, S)
    Yf, XF, energy = _centred(ctx, X, w, v)
    det = _determined(ctx, X, energy)
    if not det.any():
        return None
    fit = w.gls(XF if det.all() else XF[:, det], Yf)
    return None if fit.chi2_gain < 9.0 else (fit.beta, det)


def _half_test(ctx: Context, X: np.ndarray, m: np.ndarray, beta: np.ndarray, det: np.ndarray,
               S: np.ndarray) -> tuple[float, float | None]:
    """The chi-square the effect ``X[:, det] beta`` is expected to remove on the half
    ``m`` and the drop it brings there (None when the expected one is below 9: not
    visible), against the noise PSD ``S``, the other columns and the half's mean fitted
    freely."""
    w, v = _half(ctx, m, S)
    Yf, XF, _ = _centred(ctx, X, w, v)
    pred, free = XF[:, det] @ beta, XF[:, ~det]
    del XF
    expected = w.chi2_left(pred, free)
    if expected < 9.0:
        return expected, None
    return expected, w.chi2_left(Yf, free) - w.chi2_left(Yf - pred, free)


def judged_psd(ctx: Context, c: Candidate) -> np.ndarray:
    """The noise PSD a mean-type candidate ``c`` was judged against on the whole record
    (``candidates.base.judged_gls``): the calibrated PSD raised at the slowest
    frequencies by the flicker excess of the residual it leaves, taken out as the trial
    takes it (``candidates.base.flicker_psd``: centred), when significant (the sensor's
    own bias wander)."""
    if c.rate is None:
        return ctx.wh.S
    return flicker_psd(ctx, c.rate)


def _heldout(ctx: Context, c: Candidate) -> tuple[bool, str]:
    if c.design is not None:
        return _heldout_mean(ctx, c.design, judged_psd(ctx, c))
    if c.heldout is not None:
        # on the second half, on the first: (drop, expected[, how it was predicted[, least drop that passes]])
        res = c.heldout()
        ok = all(r[0] > (r[3] if len(r) > 3 else 0.0) for r in res if r[1] >= 9.0)
        return ok, "; ".join(f"{h} half: chi2 drop {r[0]:.1f} (expected {r[1]:.1f}"
                             + (f"; {r[2]})" if len(r) > 2 and r[2] else ")")
                             for h, r in zip(("second", "first"), res, strict=True))
    return True, "n/a (spectral or spike fit on the whole record)"


#: a fitted line this many frequency resolutions 1/T wide is resolved: band-limited
#: noise, not a coherent sinusoid
LINE_RESOLVED_BINS = 4.0


def _inside_line(c: Candidate, cands: list[Candidate], df_hz: float) -> float | None:
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


def _subtracted(c: Candidate) -> bool:
    """Whether ``c`` is taken out of the residual (the null stays): a mean-type effect, or
    outliers replaced; other noise-type effects join the stochastic model (their ``rate``,
    a vibration_lines' Wiener estimate, serves --out-corrected only)."""
    return c.nature == "mean" or c.kind == "outliers"
