"""The report's warnings about what the record cannot establish (docs/formats.md):
``record_too_short`` (model terms the record is too short to test),
``nonstationary`` (excess left after the selection that is a burst of noise, which no
stationary effect kind models), ``spikes`` (the spike test finds more than chance
but no outlier effect was accepted: every spike is listed) and ``lookalike`` (two
descriptions the record cannot tell apart)."""
from __future__ import annotations

import numpy as np

from fogmon.explain import detectors, mismatch
from fogmon.explain.analysis import Analysis
from fogmon.explain.candidates.base import Context
from fogmon.explain.candidates.coefficients import NOISE_UNIT, effect_summary
from fogmon.explain.candidates.spikes import shoulder_text, spike_evidence
from fogmon.sim.model import SensorModel

#: A slow model term the record cannot test: its share of the model's Allan variance at
#: the longest whole-record tau (duration / 4) is below this.
UNTESTABLE_SHARE = 0.1


def _span(grid: mismatch.Grid) -> tuple[float, float]:
    """The record's span (s) on ``grid``: its first sample to one sample interval past its last."""
    return grid.t0_s, grid.t0_s + grid.n / grid.sample_rate_hz


def too_short_warnings(model: SensorModel, grid: mismatch.Grid) -> list[dict]:
    """``record_too_short`` warnings (docs/formats.md): a map with fewer than 3 taus
    (window too short to show how the mismatch depends on tau), and model terms the
    record is too short to test - IEEE-952 B, K, R below UNTESTABLE_SHARE of the model's
    Allan variance even at tau = duration / 4, a periodic term with fewer than two
    periods, a Gauss-Markov correlation time beyond duration / 4."""
    from fogmon.davar.theory import coefficients_to_avar_terms

    t0, t1 = _span(grid)
    dur = t1 - t0
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


def spike_warnings(ctx: Context, rejected: list[tuple[str, float, str]],
                   accepted: list[str] | tuple[str, ...] = ()) -> tuple[list[dict], dict | None]:
    """A ``spikes`` warning and the listing of every spike (times_s s, amplitudes_dph
    deg/h, abs_z) when the spike test of the final residual (context ``ctx``) finds
    samples beyond its 1 % family-wise threshold - more than chance: when no outlier
    effect was accepted, the text says why neither description was (the refusals of
    ``glitches`` and ``outliers``, and why the tail is not a population); when one was
    (``accepted``: the kinds), that these are left after it; where the noise's broad
    shoulder sets the threshold (candidates.spikes.shoulder_law), the samples beyond a
    Gaussian noise's threshold are listed too and the text says they are that law's
    chance extremes. ([], None) when nothing lies beyond a Gaussian noise's threshold."""
    ev = spike_evidence(ctx)
    idx = ev.glitch_idx
    if not len(idx) and not len(ev.shoulder_idx):
        return [], None
    shown = np.union1d(idx, ev.shoulder_idx)
    listing = {"times_s": ctx.t_s[shown], "amplitudes_dph": ev.amp[shown], "abs_z": np.abs(ev.z[shown])}
    largest = float(np.max(listing["abs_z"]))
    if not len(idx):
        assert ev.shoulder is not None
        law = ev.shoulder
        text = (f"the noise is heavier-tailed than the model's Gaussian: the spike test's statistic is a broad "
                f"shoulder ({100 * law.eps:.3g} % of samples {law.s:.3g}x wider than the rest), which no "
                f"catalogue effect describes; the {len(shown)} sample(s) beyond a Gaussian noise's 1 % family-wise "
                f"|z| = {ev.gauss_thr:.2f} (largest {largest:.1f}) lie within that law's own, |z| = {ev.thr:.2f}, so "
                f"none is named a glitch: every one is listed in the outliers file")
        return [_spikes_warning(ctx, text)], listing
    found = (f"finds {len(idx)} sample(s) beyond |z| = {ev.thr:.2f} (1 % family-wise{shoulder_text(ev)}; "
             f"largest |z| {largest:.1f}), more than chance")
    listed = ("every one is listed in the outliers file" if not len(ev.shoulder_idx) else
              f"the outliers file lists all {len(shown)} beyond a Gaussian noise's |z| = {ev.gauss_thr:.2f}, the "
              f"shoulder's chance extremes among them")
    if accepted:
        text = (f"after the accepted {' and '.join(accepted)} effect, the spike test of the final residual still "
                f"{found}: {listed}" + (" after the outliers" if "outliers" in accepted else ""))
    else:
        why = [f"{k}: {w}" for k, _, w in rejected if k in ("glitches", "outliers")]
        if ev.not_population:
            why.append(f"outliers: not a population: {ev.not_population}")
        text = (f"the spike test {found}, but no outlier effect was accepted"
                f" ({'; '.join(why) or 'no spike description passed its bar'}): {listed}")
    return [_spikes_warning(ctx, text)], listing


def _spikes_warning(ctx: Context, text: str) -> dict:
    return {"kind": "spikes", "t_start_s": float(ctx.t_s[0]), "t_end_s": float(ctx.t_s[-1]), "text": text}


def lookalike_warnings(accepted, model: SensorModel, grid: mismatch.Grid) -> list[dict]:
    """A ``lookalike`` warning (spanning the record of ``grid``) for each accepted
    effect whose refused look-alike the record cannot tell from it (``Candidate.tie``,
    fogmon.explain.lookalike): both descriptions, with their BIC gains."""
    noise = {k: getattr(model.noise, k) for k in NOISE_UNIT}
    out = []
    for a in accepted:
        tie = a.cand.tie
        if tie is None:
            continue
        named, other = (effect_summary(k, p, noise) for k, p in ((a.cand.kind, a.cand.params),
                                                                   (tie["kind"], tie["params"])))
        t0, t1 = _span(grid)
        out.append({"kind": "lookalike", "t_start_s": t0, "t_end_s": t1,
                    "text": f"two descriptions fit the residual equally well (BIC gains {tie['own_bic_gain']:.2f} "
                            f"and {tie['bic_gain']:.2f}): {named}; or {other}. The record cannot tell them apart: "
                            f"the first is named for its larger gain; a longer record decides"})
    return out



def walk_lookalike_warnings(drifts: list, walk: SensorModel, grid: mismatch.Grid) -> list[dict]:
    """A ``lookalike`` warning for each effect ``drifts`` (accepted against the baseline
    without a rate random walk, refused against ``walk``, the baseline with the walk
    its long taus show): both descriptions; the walk is named (docs/explain.md, "The
    baseline", item 5)."""
    noise = {k: getattr(walk.noise, k) for k in NOISE_UNIT}
    t0, t1 = _span(grid)
    k = walk.noise.K_dphsh
    return [{"kind": "lookalike", "t_start_s": t0, "t_end_s": t1,
             "text": f"two descriptions fit the record: a rate random walk K {k:.4g} deg/h/sqrt(h) in the baseline "
                     f"(the whole record's long taus show it, its windows are too short to refute it); or, against "
                     f"a baseline without it, {effect_summary(a.cand.kind, a.cand.params, noise)}. The record "
                     f"cannot tell a walk's realisation from such a drift: the walk is named, the drift is not; a "
                     f"longer record decides"} for a in drifts]
