"""What every candidate shares: the ``Context`` it is fitted in, the fitted ``Candidate``,
the GLS helpers of the mean-type kinds (``unit_rate``, ``centred``, ``judged_gls``) and the spectral
helpers of the noise-type ones (binned periodogram, the model's white level and pass
band, ``replace_white``)."""
from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from fogmon.explain.fitting import (
    BinnedPeriodogram,
    GlsFit,
    Whittle,
    calibrate_psd,
    filter_gain2,
    low_band_flicker,
    model_psd,
    rfft_omega,
)
from fogmon.explain.replicas import Replicas
from fogmon.sim import effects as fx
from fogmon.sim.model import EFFECT_KINDS, Effect, Noise, SensorModel, validate_effect


@dataclass
class Context:
    """What every candidate sees: uniform time grid ``t_s`` (s), gap-filled aux channels,
    ``valid`` mask, sample rate, current residual ``y`` (deg/h, 0 where invalid), the
    current stochastic model, the calibrated Whittle GLS and the residual's DFT."""

    t_s: np.ndarray
    aux: dict
    valid: np.ndarray
    sample_rate_hz: float
    y: np.ndarray
    stoch: SensorModel
    wh: Whittle
    Yf: np.ndarray
    #: results shared by candidates within one round (the spike evidence)
    cache: dict = field(default_factory=dict, repr=False)
    #: the recording's metadata (``unit_<column>`` lines name aux channels' units)
    meta: dict = field(default_factory=dict, repr=False)
    #: the residual's first sample as given (deg/h), when ``y``'s is not (the wrap spike
    #: projected out there, analysis.whittle_context); None: ``y`` is the residual as given
    y_first: float | None = None

    def residual(self, fill: float = 0.0) -> np.ndarray:
        """The residual as given (deg/h; ``fill`` where not valid): ``y`` with its first
        sample restored (``y_first``); a new array."""
        out = np.where(self.valid, self.y, fill)
        if self.y_first is not None and len(out) and self.valid[0]:
            out[0] = self.y_first
        return out

    @property
    def n(self) -> int:
        return len(self.t_s)

    @property
    def penalty(self) -> float:
        return math.log(max(int(self.valid.sum()), 2))


@dataclass
class Candidate:
    """A fitted effect: full parameters, standard errors of the fitted ones, the
    likelihood-ratio ``gain``, parameter count ``k``, the rate it removes from the
    residual (deg/h: a mean-type effect's deterministic rate, or an outlier population's
    replacements) and the design used (for the held-out check), plus evidence."""

    kind: str
    params: dict
    se: dict
    gain: float
    k: int
    evidence: str
    rate: np.ndarray | None = None
    design: np.ndarray | None = None
    heldout: Callable | None = field(default=None, repr=False)
    #: the white level N0 (deg/sqrt(h)) the stochastic model takes with this effect
    #: (a white-level regression's intercept), None: unchanged
    white_n0_dpsh: float | None = None
    #: the stochastic model this noise-type effect joins, its white-equivalent level
    #: refitted under it (vibration_lines: with_white_level, filtered_levels); None: the current one
    stoch_base: SensorModel | None = None
    #: every sample an ``outliers`` effect holds: times_s (s), amplitudes_dph (deg/h),
    #: abs_z (arrays; written to the outliers file, not into the report)
    listing: dict | None = field(default=None, repr=False)
    #: corrected IEEE-952 coefficients (the ``noise`` kind): replace the model's [noise]
    corrected_noise: Noise | None = None
    #: the gain a chance maximum of the candidate's own search exceeds with probability
    #: SEARCH_FALSE_ALARM (a periodic term's frequency search): the bar when above BIC's
    search_bar: float = 0.0
    #: ``search_bar`` is the search's false-alarm law over every value it scans, BIC's
    #: k ln n not applied on top (the periodic term's octave bars)
    search_calibrated: bool = False
    #: the bar the model's own noise sets, simulated (scan_null: ``search_bar`` raised by
    #: the replicates' chance excess over it); 0: none
    chance_bar: float = 0.0
    #: a refused look-alike the record cannot tell from this effect (lookalike.explained):
    #: {"kind", "params", "bic_gain", "own_bic_gain"}; None when there is none
    tie: dict | None = None

    @property
    def nature(self) -> str:
        return EFFECT_KINDS[self.kind].nature

    def bic_bar(self, penalty: float) -> float:
        """BIC's bar k ln n, 0 for a search whose own law is its bar (``search_calibrated``)."""
        return 0.0 if self.search_calibrated else self.k * penalty

    def bar(self, penalty: float) -> float:
        """The bar its gain must pass: the highest of BIC's (``bic_bar``), its search's
        (``search_bar``) and the simulated one (``chance_bar``)."""
        return max(self.bic_bar(penalty), self.search_bar, self.chance_bar)

    def bic_gain(self, penalty: float) -> float:
        """The gain above the bar (``bar``)."""
        return self.gain - self.bar(penalty)

    def effect(self) -> Effect:
        return validate_effect(self.kind, self.params, "fitted effect")


def varies(a: np.ndarray) -> bool:
    """Whether channel ``a`` varies beyond float rounding: its finite values' range above
    1e-9 of their largest magnitude (the mean of a channel held at 0.02 is 0.02 only to
    1e-17; such a spread, regressed on, gives any slope with a tiny standard error)."""
    f = np.asarray(a, dtype=float)
    f = f[np.isfinite(f)]
    return f.size > 1 and float(np.ptp(f)) > 1e-9 * float(np.max(np.abs(f)))


def unit_rate(kind: str, params: dict, ctx: Context) -> np.ndarray:
    """Rate (deg/h) of a mean-type effect with the given parameters on the context grid."""
    return fx.mean_rate_dph(validate_effect(kind, params, "candidate"), ctx.t_s, ctx.aux, ctx.sample_rate_hz)


def centred(rate: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """A mean-type effect's ``rate`` (deg/h) as it is taken out of the residual: less its
    mean over the ``valid`` samples (a new array). The residual is centred over them
    (the model's bias takes the effect's mean) and stays so wherever an effect is tried,
    judged or accepted (``judged_gls``, ``flicker_psd``, ``Selection.trial``): in a
    record cut into pieces an offset left, zeroed in the gaps, is gate-shaped
    low-frequency power - a flicker excess, or a spectral term's gain."""
    return rate - (np.mean(rate[valid]) if valid.any() else 0.0)


def flicker_psd(ctx: Context, rate: np.ndarray) -> np.ndarray:
    """The calibrated PSD raised at the slowest frequencies by the flicker excess the
    residual shows once the mean-type effect ``rate`` (deg/h) is taken out (``centred``),
    when significant (low_band_flicker); ``ctx.wh.S`` itself otherwise."""
    return low_band_flicker(ctx.wh.S, ctx.Yf - ctx.wh.fft(centred(rate, ctx.valid)), ctx.n)


def judged_gls(ctx: Context, X: np.ndarray, Xf: np.ndarray | None = None) -> GlsFit:
    """Whittle GLS of the residual on the design ``X`` (n x p; ``Xf``: its transform,
    ``ctx.wh.fft(X)`` when not given), judged against the noise its own residual shows
    at the slowest frequencies: refitted with the PSD raised there by that residual's
    significant flicker excess (``flicker_psd``), so a drift, step or settling that is
    significant only against a model PSD extrapolated below its calibrated band - not
    against the sensor's own bias wander - loses that significance (its gain,
    coefficients and standard errors are the refit's). Where the model's noise has long
    memory, its covariance is the estimator's under the model's law (``exact_cov_fit``)."""
    return judged_whittle(ctx, X, Xf)[0]


def judged_whittle(ctx: Context, X: np.ndarray, Xf: np.ndarray | None = None) -> tuple[GlsFit, Whittle]:
    """``judged_gls`` and the Whittle GLS it was fitted by (``ctx.wh``, or the raised PSD's)."""
    if Xf is None:
        Xf = ctx.wh.fft(X)
    wh = ctx.wh
    fit = wh.gls(Xf, ctx.Yf)
    S = flicker_psd(ctx, X.reshape(ctx.n, -1) @ fit.beta)
    if S is not wh.S:
        wh = Whittle(S, ctx.n, ctx.valid)
        fit = wh.gls(Xf, ctx.Yf)
    return (fit if exact_law(ctx) is None else exact_cov_fit(ctx, fit, wh, Xf)), wh


#: ``Context.cache`` keys: LONG_MEMORY True marks the record's own context (not a bootstrap
#: replicate's) when its model's noise has long memory (scan_null.calibrated_kinds); the
#: mean-type fits' standard errors are then those of their estimator under the model's law
#: (``exact_cov_fit``), held under EXACT_LAW while in use (``exact_law``)
LONG_MEMORY, EXACT_LAW = "long_memory", "exact_law"


def exact_law(ctx: Context) -> Replicas | None:
    """The law of the context's stochastic model (``replicas.Replicas``) when its errors
    are to be exact (``LONG_MEMORY``), built once per context (and again after a
    selection round lets it go: memory), else None; None too for a model with a
    ``bandwidth`` filter (the law filters every term, which ``Replicas.functional_cov``
    does not follow: such a record keeps the Whittle errors)."""
    if not ctx.cache.get(LONG_MEMORY) or any(EFFECT_KINDS[e.kind].nature == "filter" for e in ctx.stoch.effects):
        return None
    if EXACT_LAW not in ctx.cache:
        ctx.cache[EXACT_LAW] = Replicas(ctx.stoch, ctx.t_s, ctx.aux, ctx.valid)
    return ctx.cache[EXACT_LAW]


def exact_cov_fit(ctx: Context, fit: GlsFit, wh: Whittle, Xf: np.ndarray) -> GlsFit:
    """``fit`` (of the design ``Xf`` to the context's residual by ``wh``) with the covariance
    its estimator has under the model's law (``exact_law``) rather than the one the Whittle
    likelihood states. That likelihood takes the record as circular with independent DFT
    bins; a rate random walk's wrap jump and the leakage of a steep (flicker) PSD break
    that, and the stated errors of steps, ramps and settlings were 1.4-5.7x too small
    (docs/explain.md, "Standard errors under long memory"); with gaps the stated covariance
    is not even the circular one. The estimator is linear, beta = a @ y
    (``Whittle.weights``), so its covariance under the law's Gaussian terms is exact
    (``Replicas.functional_cov``, E). The model's other terms count as the Whittle fit
    counts them (``Whittle.circulant_covs`` of the model's PSD less that of the law's
    terms, ``Replicas.law_psd``); each coefficient's row and column are scaled by the
    record's noise level against the model's as its weights see it (the model's PSD
    calibrated to the residual less the fitted effect, ``calibrated_psd``, over the model's
    own: the effect's power is not noise); and a PSD the fit raised for the residual's own
    flicker excess (``flicker_psd``) adds what it raised, as the fit counts it."""
    law = exact_law(ctx)
    assert law is not None
    a = wh.weights(Xf, fit.cov)
    S_model = model_psd_full(ctx)
    S_rec = calibrated_psd(ctx.stoch, S_model, ctx.Yf - Xf.reshape(len(ctx.Yf), -1) @ fit.beta, ctx.n)
    model, terms, record, used, base = wh.circulant_covs(a, S_model, law.law_psd(), S_rec, wh.S, ctx.wh.S)
    cov = law.functional_cov(a) + model - terms
    with np.errstate(divide="ignore", invalid="ignore"):
        level = np.sqrt(np.diag(record) / np.diag(model))
    if not (np.all(np.isfinite(level)) and np.all(np.diag(cov) > 0)):
        return fit
    return GlsFit(fit.beta, cov * np.outer(level, level) + (used - base), fit.chi2_gain)


def calibrated_psd(stoch: SensorModel, S_model: np.ndarray, Yf: np.ndarray, n: int) -> np.ndarray:
    """The model's PSD ``S_model`` (at the rfft bins of ``n`` samples) floored at
    LEAKAGE_FLOOR x its median and calibrated to the transformed residual ``Yf`` per octave
    band (``fitting.calibrate_psd``) over the model's pass band (``in_passband``), +inf
    outside it: the PSD of the candidates' fits (analysis.whittle_context)."""
    S = np.maximum(S_model, LEAKAGE_FLOOR * np.median(S_model[1:]))  # a PSD near 0 must not give one bin all the weight
    keep = in_passband(stoch, rfft_omega(n))
    out = np.full(len(S), np.inf)
    out[keep] = calibrate_psd(S[keep], Yf[keep], n)  # a low-pass's pass band: the bins 0..K
    return out


def estimate_text(x: float, se: float) -> str:
    """``x +- se`` for an evidence text."""
    return f"{x:.4g} +- {se:.2g}"


#: the held-out note of a half whose own fit finds nothing, so that it predicts with the
#: whole record's fit (the held-out checks of ``noise`` and ``markov``)
WHOLE_RECORD_NOTE = "the whole record's fit: the other half alone finds nothing"


def periodogram(ctx: Context, part: slice | None = None) -> BinnedPeriodogram:
    """Binned periodogram of the residual (computed once per context), or of ``part`` of it;
    when the model holds a rate random walk, of the residual without its line (``bridged``)."""
    walk = ctx.stoch.noise.K_dphsh > 0
    if part is None:
        if "periodogram" not in ctx.cache:
            Yf = np.fft.rfft(bridged(ctx.y, ctx.valid)) if walk else ctx.Yf  # ctx.y is 0 where not valid
            ctx.cache["periodogram"] = BinnedPeriodogram(Yf, ctx.n)
        return ctx.cache["periodogram"]
    y = np.where(ctx.valid[part], ctx.y[part], 0.0)
    return BinnedPeriodogram(np.fft.rfft(bridged(y, ctx.valid[part]) if walk else y), len(y))


def bridged(y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``y`` (deg/h, 0 where not ``valid``) less its least-squares line over the valid
    samples (0 where not valid): what the spectral tests (the Whittle deviances of the
    noise-type candidates) read when the model holds a rate random walk K. A random walk's
    periodic extension jumps at the record's wrap by its whole excursion, and the DFT of
    that jump is a 1/f^2 term common to every bin, so its bins are neither independent nor
    distributed as the walk's PSD, as the Whittle likelihood assumes: a large excursion
    raised the lowest bins together (a 10 Hz, 1.8 h null record of N, B and K: the 4
    lowest at 6-9x the model's PSD) and a B 1.6x the truth won a deviance of 36 over BIC's
    11 (docs/explain.md, "Spectral tests under a rate random walk"). Less its line, the
    walk is close to a bridge, whose DFT bins are independent with the walk's PSD."""
    t = np.flatnonzero(valid).astype(float)
    if len(t) < 3:
        return y
    v = y[valid]
    tc = t - t.mean()
    slope = float(np.dot(tc, v - v.mean()) / np.dot(tc, tc))
    out = np.zeros(len(y))
    out[valid] = v - v.mean() - slope * tc
    return out


def model_psd_full(ctx: Context) -> np.ndarray:
    """The current stochastic model's PSD at every rfft bin of the record, with the RMS of
    its white level (``white_rms_dpsh``): computed once per context (analysis.whittle_context)."""
    if "model_psd" not in ctx.cache:
        ctx.cache["model_psd"] = model_psd(ctx.stoch, rfft_omega(ctx.n), ctx.n, white_rms_dpsh(ctx.stoch, ctx))
    return ctx.cache["model_psd"]


def passband_part(ctx: Context, bp: BinnedPeriodogram) -> BinnedPeriodogram:
    """``bp`` over the model's pass band (``in_passband``)."""
    keep = in_passband(ctx.stoch, bp.omega)
    if keep.all():
        return bp
    band = copy.copy(bp)
    band.count, band.I, band.k, band.omega = bp.count[keep], bp.I[keep], bp.k[keep], bp.omega[keep]
    return band


def white_rms_dpsh(model: SensorModel, ctx: Context) -> float:
    """RMS over the record of the white level N(t) = N0 + white-level effects (deg/sqrt(h))."""
    return white_level_rms_dpsh(model, ctx.t_s, ctx.aux)


def white_level_rms_dpsh(model: SensorModel, t_s: np.ndarray, aux: dict) -> float:
    """``white_rms_dpsh`` from the sample times ``t_s`` (s) and aux channels alone."""
    level = np.full(len(t_s), model.noise.N_dpsh)
    for e in model.effects:
        if EFFECT_KINDS[e.kind].nature == "white_level":
            level = level + fx.white_level_dpsh(e, t_s, aux)
    return float(np.sqrt(np.mean(np.maximum(level, 0.0) ** 2)))


def stoch_psd(ctx: Context, bp: BinnedPeriodogram) -> np.ndarray:
    """The current stochastic model's PSD at the bins of ``bp``."""
    return model_psd(ctx.stoch, bp.omega, ctx.n, white_rms_dpsh(ctx.stoch, ctx))


#: the calibrated Whittle GLS of the mean-type candidates and the spike test
#: (analysis.whittle_context), the markov fit and the lines' proposals keep the frequencies
#: where the model's ``bandwidth`` filters pass at least this share of the power (|H|^2, -20 dB)
PASSBAND_MIN_GAIN2 = 0.01


def passband_gain2(model: SensorModel, omega: np.ndarray) -> np.ndarray:
    """|H|^2 of the model's ``bandwidth`` filters at ``omega`` (rad/sample; 1 without a
    filter); the pass band is where it is at least PASSBAND_MIN_GAIN2. Beyond it the
    model PSD is orders of magnitude below its pass-band level (floored in the fits),
    so a likelihood there measures the filter's exact shape (on a real sensor the
    fitted filter is not the real one), not a term under it; and a term there is
    attenuated by the filter as much as the noise."""
    G = np.ones(len(omega))
    for e in model.effects:
        if e.kind == "bandwidth":
            G = G * filter_gain2(e.params, float(model.sample_rate_hz), omega)
    return G


def in_passband(model: SensorModel, omega: np.ndarray) -> np.ndarray:
    """The frequencies ``omega`` (rad/sample) where the model's ``bandwidth`` filters pass
    at least PASSBAND_MIN_GAIN2 of the power (all of them without a filter)."""
    return passband_gain2(model, omega) >= PASSBAND_MIN_GAIN2


#: PSD floor relative to the median model PSD in the spectral fits (periodogram leakage)
LEAKAGE_FLOOR = 1e-4


def replace_white(model: SensorModel, N: float, drop_other: bool = False) -> SensorModel:
    """``model`` with white level N (deg/sqrt(h)); ``drop_other``: that white noise alone
    (through the model's filters), without the other terms."""
    nz = model.noise
    noise = Noise(0.0, N, 0.0, 0.0, 0.0) if drop_other else Noise(nz.Q_arcsec, N, nz.B_dph, nz.K_dphsh, nz.R_dphh)
    eff = [e for e in model.effects
           if e.kind == "bandwidth" or (not drop_other and e.kind in ("markov", "lowpass_noise", "vibration_lines"))]
    return SensorModel(model.sample_rate_hz, model.bias_dph, noise, eff)
