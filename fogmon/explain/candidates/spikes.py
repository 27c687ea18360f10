"""Spike candidates: the robust spike test of the residual and its two descriptions,
isolated ``glitches`` listed one by one or a heavy-tailed ``outliers`` population
(rate and amplitude distribution), whichever has the larger BIC gain."""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from fogmon.explain import detectors
from fogmon.explain.candidates.base import Candidate, Context, model_psd_full
from fogmon.explain.candidates.coefficients import expected_avar
from fogmon.sim import effects as fx
from fogmon.sim.model import EFFECT_KINDS, OUTLIER_QUANTILE_PROBS, SensorModel


def white_profile(model: SensorModel, ctx: Context) -> np.ndarray | None:
    """The model's own white-noise level over time relative to its RMS (1 on average),
    or None when it is constant (no white-level effect: vibration_noise,
    temperature_noise)."""
    if not any(EFFECT_KINDS[e.kind].nature == "white_level" for e in model.effects):
        return None
    level = np.full(ctx.n, model.noise.N_dpsh)
    for e in model.effects:
        if EFFECT_KINDS[e.kind].nature == "white_level":
            level = level + fx.white_level_dpsh(e, ctx.t_s, ctx.aux)
    level = np.maximum(level, 0.0)
    rms = float(np.sqrt(np.mean(level ** 2)))
    return np.maximum(level / rms, 1e-3) if rms > 0 else None


def spike_scan(ctx: Context, y: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """GLS amplitude (deg/h) and robust z of a one-sample spike at every sample
    (detectors.spike_scan) of the residual (``y``, default the context's: computed once
    per context). When the
    model's white level varies in time (vibration- or temperature-driven ARW), the
    residual is first divided by that level, so a sample that is large only because the
    model itself is noisier there is not a spike."""
    if y is None and "spike_scan" in ctx.cache:
        return ctx.cache["spike_scan"]
    sep = detectors.kernel_length(ctx.wh)
    block = _scale_block(sep)
    prof = white_profile(ctx.stoch, ctx)
    if prof is None:
        out = detectors.spike_scan(ctx.wh, ctx.Yf if y is None else ctx.wh.fft(y), block=block)
    else:
        amp, z = detectors.spike_scan(ctx.wh, ctx.wh.fft((ctx.y if y is None else y) / prof), block=block)
        out = amp * prof, z
    if y is None:
        ctx.cache["spike_scan"] = out
    return out


def _scale_block(sep: int) -> int:
    """Samples per block of the spike statistic's local robust scale: many matched-filter
    half-widths ``sep`` (the z of neighbouring samples correlate over that length)."""
    return max(4096, 64 * sep)


@dataclass
class SpikeEvidence:
    """The spike test of one residual and its two descriptions: ``glitch_idx`` (every
    sample beyond the Bonferroni threshold, local maxima ``sep`` apart, ``z`` scaled by
    the robust scale of the noise without them: detectors.find_spikes_step_down) with the BIC
    gain of listing them one by one, and the contaminated-Gaussian ``law`` of all z
    (None: no tail) with the BIC gain of describing them as a population."""

    amp: np.ndarray
    z: np.ndarray
    sep: int
    thr: float
    glitch_idx: np.ndarray
    bic_glitches: float
    law: detectors.Contamination | None
    bic_population: float
    #: why the spikes are not an outlier population ("" when they are)
    not_population: str = ""
    #: the Gaussian Bonferroni threshold; the noise's own broad-shouldered law when it sets
    #: ``thr`` instead (:func:`shoulder_law`), and the samples beyond the Gaussian
    #: threshold that are its chance extremes
    gauss_thr: float = 0.0
    shoulder: detectors.Contamination | None = None
    shoulder_idx: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def population(self) -> bool:
        """Outliers are a population when that description has the larger BIC gain and
        the tail is one of rare, far, time-homogeneous outliers (``not_population``)."""
        return not self.not_population and self.bic_population > max(self.bic_glitches, 0.0)


#: parameters an outlier population carries in the model: rate, positive fraction and
#: the amplitude quantiles (what its BIC pays for)
POPULATION_K = 2 + len(OUTLIER_QUANTILE_PROBS)


def spike_evidence(ctx: Context) -> SpikeEvidence:
    """Spike test of the context's residual and its glitch/population descriptions
    (computed once per context). The population's likelihood gain is the
    contaminated-Gaussian fit over every tested z, divided by ``sep`` (a spike lights up
    about ``sep`` correlated z values when the noise is coloured, which a sum over samples
    would count ``sep`` times). The threshold is N(0, 1)'s 1 % family-wise one, or that of
    the noise's own law where its tail is a broad shoulder (:func:`shoulder_law`)."""
    if "spikes" in ctx.cache:
        return ctx.cache["spikes"]
    sep = detectors.kernel_length(ctx.wh)
    amp, z = spike_scan(ctx)
    nv = int(ctx.valid.sum())
    gauss_thr = detectors.bonferroni_z(nv)
    z, idx = detectors.find_spikes_step_down(z, gauss_thr, min_sep=sep, block=_scale_block(sep))
    tested = ctx.valid & (z != 0.0)
    law = detectors.fit_contamination(z[tested])
    not_pop = _not_population(law, z, tested)
    thr, chance = gauss_thr, idx[:0]
    shoulder = _shoulder(law, z, tested, nv, sep, ctx.penalty)
    if shoulder is not None:
        thr = shoulder.bonferroni_z(nv)
        far = np.abs(z[idx]) > thr
        idx, chance = idx[far], idx[~far]
    bic_g = float(np.sum(z[idx] ** 2)) - 2 * len(idx) * ctx.penalty if len(idx) else 0.0
    bic_p = law.gain / sep - POPULATION_K * ctx.penalty if law is not None else 0.0
    ev = SpikeEvidence(amp, z, sep, thr, idx, bic_g, law, bic_p, not_pop, gauss_thr, shoulder, chance)
    ctx.cache["spikes"] = ev
    return ev


#: an outlier population's contaminated samples spread at least this many times wider
#: than the clean noise (a narrower excess is a heavier-shouldered noise or a noise
#: level varying in time, which the map reports)
OUTLIER_MIN_SD_RATIO = 3.0
#: blocks of the record in which the outliers' occurrence must look homogeneous
OUTLIER_BLOCKS = 16


def shoulder_law(law: detectors.Contamination | None, sep: int, penalty: float) -> bool:
    """Whether the spike statistic's tail is the noise's own broad shoulder, so that its
    chance extremes are that law's and not the normal's: the contaminated-Gaussian fit
    is too narrow to be a population of far outliers (a spread under OUTLIER_MIN_SD_RATIO
    x the clean noise's), and it beats N(0, 1) by BIC (its 2 parameters, the gain per
    independent statistic: ``sep``). Real residuals have such shoulders (the G ring
    laser's quiet record: 3.8 % of samples 1.8x wider); N(0, 1)'s 1 % family-wise
    threshold would call their tail glitches, the law's does not. A far wider component
    (a contaminated record's 40 % of samples 5x wider) keeps N(0, 1)'s threshold: its
    samples beyond it are listed as glitches."""
    return law is not None and law.s < OUTLIER_MIN_SD_RATIO and law.gain / sep > 2.0 * penalty


#: refits of the shoulder without the samples beyond its own threshold, at most
SHOULDER_REFITS = 3


def _shoulder(law: detectors.Contamination | None, z: np.ndarray, tested: np.ndarray, nv: int, sep: int,
              penalty: float) -> detectors.Contamination | None:
    """The noise's broad-shouldered law (None: its tail is not one, :func:`shoulder_law`),
    fitted without the samples beyond its own 1 % family-wise threshold: by that law they
    are not its members, and a few far glitches among them would widen it and raise the
    threshold that is to find them (refitted until the threshold stays, at most
    SHOULDER_REFITS times)."""
    if not shoulder_law(law, sep, penalty):
        return None
    assert law is not None
    thr = law.bonferroni_z(nv)
    for _ in range(SHOULDER_REFITS):
        inner = detectors.fit_contamination(z[tested & (np.abs(z) <= thr)])
        if inner is None or not shoulder_law(inner, sep, penalty):
            break
        law, thr_was, thr = inner, thr, inner.bonferroni_z(nv)
        if abs(thr - thr_was) < 0.01:
            break
    return law


def _not_population(law: detectors.Contamination | None, z: np.ndarray, tested: np.ndarray) -> str:
    """Why the tail of the spike statistic is not a population of rare outliers ("" when
    it is): no tail; a contaminated part not far from the clean noise (spread under
    OUTLIER_MIN_SD_RATIO x) or not a minority (over 10 %); or outliers not occurring
    at one rate over the record (counts beyond the even-odds point in OUTLIER_BLOCKS
    blocks over-dispersed against Poisson at 1 %: bursts of a higher noise level, not a
    rare shock process)."""
    if law is None:
        return "no tail beyond |z| = 4"
    if law.s < OUTLIER_MIN_SD_RATIO or law.eps > 0.1:
        return (f"the tail is a broad shoulder ({100 * law.eps:.3g} % of samples {law.s:.3g}x wider than the rest), "
                f"not rare far outliers")
    cut = law.z_even
    edges = np.linspace(0, len(z), OUTLIER_BLOCKS + 1).astype(np.int64)
    cs = np.concatenate(([0], np.cumsum(tested & (np.abs(z) > cut))))[edges]
    cv = np.concatenate(([0], np.cumsum(tested)))[edges]
    c, v = np.diff(cs), np.diff(cv)
    e = c.sum() * v / max(v.sum(), 1)
    use = e > 0
    disp = float(np.sum((c[use] - e[use]) ** 2 / e[use]))
    dof = int(use.sum()) - 1
    if dof > 0 and stats.chi2.sf(disp, dof) < 0.01:
        return (f"the outliers do not occur at one rate: their counts in {OUTLIER_BLOCKS} blocks scatter "
                f"{disp / dof:.3g}x as much as a Poisson process's (p = {stats.chi2.sf(disp, dof):.2g}): bursts "
                f"of a higher noise level, not a rare shock process")
    return ""


def shoulder_text(ev: SpikeEvidence) -> str:
    """How the noise's broad shoulder set the spike threshold ("" when it did not)."""
    if ev.shoulder is None or ev.thr <= ev.gauss_thr:
        return ""
    return (f" under the noise's own broad-shouldered law, {100 * ev.shoulder.eps:.3g} % of samples "
            f"{ev.shoulder.s:.3g}x wider than the rest; a Gaussian noise's threshold is {ev.gauss_thr:.2f}, and the "
            f"{len(ev.shoulder_idx)} sample(s) between are that law's chance extremes")


#: the white level is refitted with the spikes removed when the cleaned residual's
#: shortest-tau Allan variance lies this many standard errors below the model's
WHITE_REFIT_Z = 4.0


def white_without(ctx: Context, rate: np.ndarray) -> float | None:
    """The white level N0 (deg/sqrt(h)) the stochastic model takes once the spikes ``rate``
    (deg/h) are taken out of the residual, or None (unchanged). A model whose N was read
    from the record with its outliers in it (the baseline, or a datasheet measured so)
    holds their variance as white noise: without them the record is quieter than that
    model at every tau, and the map would count the removal against them. When the
    cleaned residual's Allan variance at the shortest tau lies WHITE_REFIT_Z standard
    errors below the model's, N^2 drops by that deficit in white units, at most by the
    variance the spikes removed (never below a tenth of N)."""
    v = ctx.valid
    pair = v[1:] & v[:-1]
    m = int(pair.sum())
    if m < 16:
        return None
    y1 = np.where(v, ctx.y - rate, 0.0)
    a_raw = 0.5 * float(np.mean(np.diff(ctx.y)[pair] ** 2))
    a_clean = 0.5 * float(np.mean(np.diff(y1)[pair] ** 2))
    a_model = float(expected_avar(model_psd_full(ctx), ctx.n, np.array([1]))[0])
    if not a_model - a_clean > WHITE_REFIT_Z * a_model * math.sqrt(3.0 / m):
        return None
    drop = min(a_model - a_clean, a_raw - a_clean)
    n_old = ctx.stoch.noise.N_dpsh
    if drop <= 0 or n_old <= 0:
        return None
    return math.sqrt(max(n_old ** 2 - drop / (3600.0 * ctx.sample_rate_hz), (0.1 * n_old) ** 2))


def _refit_note(n_old: float, n0: float | None) -> str:
    return ("" if n0 is None else
            f"; without them the record is quieter than the model: its white level N refitted "
            f"{n_old:.4g} -> {n0:.4g} deg/sqrt(h) (the model's N held the outliers' variance)")


def glitches(ctx: Context) -> Candidate | None:
    """Isolated spikes: GLS matched filter at every sample, robust (MAD) scale of the
    noise without the spikes (a step-down: detectors.find_spikes_step_down), the model's
    own white-level profile divided out, Bonferroni threshold over all samples (1 %
    family-wise); every one listed (when an outlier population describes them better,
    :func:`outliers` has the larger BIC gain and is tried first)."""
    ev = spike_evidence(ctx)
    idx = ev.glitch_idx
    if not len(idx):
        return None
    amp, z, thr = ev.amp, ev.z, ev.thr
    times = (ctx.t_s[idx]).tolist()
    amps = amp[idx].tolist()
    rate = np.zeros(ctx.n)
    rate[idx] = amp[idx]
    gain = float(np.sum(z[idx] ** 2))
    zmax = float(np.max(np.abs(z[idx])))
    pop = (f"; not an outlier population: {ev.not_population}" if ev.not_population else
           f"; as an outlier population the BIC gain would be {ev.bic_population:.1f} (vs {ev.bic_glitches:.1f} "
           f"listed one by one)")
    text = (f"robust spike test: {len(idx)} sample(s) beyond |z| = {thr:.2f} (1 % family-wise over "
            f"{int(ctx.valid.sum())} samples{shoulder_text(ev)}), largest |z| = {zmax:.1f}, amplitudes "
            f"{np.min(np.abs(amps)):.3g}..{np.max(np.abs(amps)):.3g} deg/h{pop}")
    se = {"amplitudes_dph": float(1.0 / math.sqrt(np.sum(ctx.wh.w)))}
    n0 = white_without(ctx, rate)
    text += _refit_note(ctx.stoch.noise.N_dpsh, n0)
    return Candidate("glitches", {"times_s": times, "amplitudes_dph": amps}, se, gain,
                     2 * len(idx) + (n0 is not None), text, rate, None, white_n0_dpsh=n0)


#: the outlier search repeats the spike scan on the cleaned residual at most this often
#: (a cluster of outlying samples is found peak first, then its neighbours)
OUTLIER_PASSES = 4
#: seed of the noise drawn for the replaced outlier samples (reproducible reports)
OUTLIER_FILL_SEED = 20261126


def outliers(ctx: Context) -> Candidate | None:
    """A heavy-tailed outlier population (kind ``outliers``): when the contaminated-
    Gaussian description of the spike test beats listing glitches one by one (BIC), every
    sample more likely contaminated than clean (|z| beyond the mixture's even-odds point,
    or the Bonferroni threshold if lower) is an outlier; the scan is repeated on the
    cleaned residual (clusters). Each outlier is replaced by the GLS interpolation from
    its neighbours plus a draw of the model's conditional noise there (so the rest keeps
    the model's noise statistics). Rate, |amplitude| quantiles and the mixture are the
    effect's parameters; ``times_s``/``amplitudes_dph``/``abs_z`` go to the outliers file."""
    if any(e.kind == "outliers" for e in ctx.stoch.effects):
        return None
    ev = spike_evidence(ctx)
    if not ev.population:
        return None
    law = ev.law
    assert law is not None  # a population needs a fitted law (bic_population is 0 without one)
    z_cut = min(law.z_even, ev.thr)
    se = np.where(ev.z != 0.0, np.abs(ev.amp / np.where(ev.z != 0.0, ev.z, 1.0)), 0.0)
    se = np.where(se > 0, se, float(np.median(se[se > 0])) if (se > 0).any() else 0.0)
    removed, first_z = _outlier_passes(ctx, ev, z_cut)
    idx = np.flatnonzero(first_z > 0)
    if not len(idx):
        return None
    a = removed[idx]
    fill = np.random.default_rng([OUTLIER_FILL_SEED, len(idx)]).standard_normal(len(idx)) * se[idx]
    rate = np.zeros(ctx.n)
    rate[idx] = a - fill
    hours = int(ctx.valid.sum()) / ctx.sample_rate_hz / 3600.0
    nv = int(ctx.valid.sum())
    q = np.quantile(np.abs(a), OUTLIER_QUANTILE_PROBS)
    params = {"rate_per_h": len(idx) / hours, "amplitude_quantiles_dph": q.tolist(),
              "quantile_probs": list(OUTLIER_QUANTILE_PROBS), "positive_fraction": float(np.mean(a > 0)),
              "count": len(idx), "rate_per_sample": len(idx) / nv,
              "contamination_fraction": law.eps, "contamination_sd_ratio": law.s}
    text = (f"robust spike test: {len(idx)} outlier sample(s) (|z| beyond {z_cut:.2f}, where a sample is as likely "
            f"contaminated as clean) among {nv} samples: {len(idx) / hours:.4g} per hour, {len(idx) / nv:.3g} per "
            f"sample; |amplitude| median {q[3]:.3g} deg/h, 90 % {q[5]:.3g}, 99 % {q[6]:.3g}, largest {q[-1]:.3g} "
            f"deg/h; contaminated-Gaussian fit of the spike statistic: {100 * law.eps:.3g} % of samples with "
            f"{law.s:.3g}x the clean spread. A population, not glitches: BIC gain {ev.bic_population:.1f} as a "
            f"rate and amplitude distribution ({POPULATION_K} parameters) vs {ev.bic_glitches:.1f} listing "
            f"{len(ev.glitch_idx)} glitch(es) one by one; outliers replaced by the interpolation from their "
            f"neighbours plus the model's conditional noise")
    n0 = white_without(ctx, rate)
    text += _refit_note(ctx.stoch.noise.N_dpsh, n0)
    return Candidate("outliers", params, {"rate_per_h": math.sqrt(len(idx)) / hours}, law.gain / ev.sep,
                     POPULATION_K + (n0 is not None), text, rate, None,
                     functools.partial(_population_heldout, ctx, ev), white_n0_dpsh=n0,
                     listing={"times_s": ctx.t_s[idx], "amplitudes_dph": a, "abs_z": first_z[idx]})


def _outlier_passes(ctx: Context, ev, z_cut: float) -> tuple[np.ndarray, np.ndarray]:
    """The spike scan repeated on the cleaned residual (clusters), at most OUTLIER_PASSES
    times: per sample the amplitude removed (deg/h) and the |z| it was first found at (0:
    not an outlier)."""
    removed = np.zeros(ctx.n)
    first_z = np.zeros(ctx.n)
    amp, z = ev.amp, ev.z
    y = ctx.y.copy()
    for _ in range(OUTLIER_PASSES):
        new = detectors.find_spikes(z, z_cut, min_sep=ev.sep)
        new = new[first_z[new] == 0.0]
        if not len(new):
            break
        removed[new] += amp[new]
        first_z[new] = np.abs(z[new])
        y[new] -= amp[new]
        amp, z = spike_scan(ctx, np.where(ctx.valid, y, 0.0))
    return removed, first_z


def _population_heldout(ctx: Context, ev) -> list[tuple[float, float]]:
    """The held-out check of an outlier population: the contamination law fitted on one
    half of the record, its log-likelihood gain on the other half against the gain it
    claims there (per independent spike statistic), both ways."""
    tested = ctx.valid & (ev.z != 0.0)
    half = np.arange(ctx.n) < ctx.n // 2
    res = []
    for fit_m, test_m in ((half, ~half), (~half, half)):
        law_f = detectors.fit_contamination(ev.z[tested & fit_m])
        zt = ev.z[tested & test_m]
        if law_f is None:
            res.append((0.0, 0.0))
            continue
        share = len(zt) / max(int((tested & fit_m).sum()), 1)
        res.append((law_f.loglik_gain(zt) / ev.sep, law_f.gain / ev.sep * share))
    return res
