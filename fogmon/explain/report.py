"""Outputs of `fogmon explain`: the JSON report (docs/formats.md, plus extra keys),
a console summary, a PNG of the evidence and an optional Rerun .rrd with the same.

Extra report keys beyond the contract (added, never renamed): ``mismatches_after``,
per-region ``tau_peak_s`` and ``windows_span_s``,
``score_components_before/after``, per-effect ``uncertainty``, ``heldout``,
``bic_gain``, per ``noise`` effect ``model_noise`` (the model's values it corrects),
``refused`` candidates and ``method`` (window, hop, taus, bootstrap size,
family-wise threshold). An ``outliers`` effect's every outlier goes to the CSV its
``times_file`` names (``outliers_path``: REPORT.outliers.csv) and to the .rrd."""
from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import replace

import numpy as np

from fogmon.explain.baseline import low_pass_index
from fogmon.explain.candidates.coefficients import NOISE_UNIT, effect_summary
from fogmon.explain.detectors import spectral_lines, tau_band_hz
from fogmon.explain.explainer import Result
from fogmon.explain.mismatch import CHANCE_SCORE
from fogmon.formats.replay_log import write_replay_log
from fogmon.sim.model import Effect, SensorModel, save_model
from fogmon.sim.noise import lowpass_impulse


def json_safe(x):
    """JSON-safe plain Python numbers (NaN/inf -> None)."""
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _region_text(r: dict) -> str:
    where = "whole record" if r["whole_record"] else f"t = {r['t_start_s']:.6g}..{r['t_end_s']:.6g} s"
    if r.get("t_peak_s") is not None:
        where += f" (strongest at t = {r['t_peak_s']:.6g} s)"
    kind = "noisier than the model" if r["sign"] == "excess" else "quieter than the model"
    return (f"{where}, tau {r['tau_min_s']:.4g}..{r['tau_max_s']:.4g} s: recording {kind} "
            f"(ADEV ratio {r['ratio']:.3g}, max |z| {r['max_abs_z']:.3g}, p = {r['p_value']:.2g})")


def _model_noise(res: Result) -> dict:
    nz = res.model.noise
    return {k: getattr(nz, k) for k in NOISE_UNIT}


def baseline_low_pass(model: SensorModel) -> dict | None:
    """The baseline's low-pass-filtered white noise (``baseline.low_pass_index``, docs/explain.md,
    "The baseline"): ``kind`` (``markov``: a first-order Gauss-Markov term; ``lowpass_noise``:
    white noise through a Butterworth low-pass), ``order``, ``corner_hz`` (1 / (2 pi tau_c),
    or the Butterworth -3 dB cutoff), ``sigma_dph`` (deg/h), ``tau_c_s`` (s, markov only,
    else None), ``floor_N_dpsh`` (the unfiltered white noise N beside it, deg/sqrt(h)) and
    ``white_N_dpsh``, the white-noise level (deg/sqrt(h)) of both at taus far beyond the
    corner: N_f^2 + floor^2, (60 N_f)^2 the filtered part's PSD at 0 per unit normalized
    frequency / fs (markov: sigma^2 tau0 (1 + a) / (1 - a), a = exp(-tau0 / tau_c);
    lowpass_noise: sigma^2 tau0 / sum of h^2, h its impulse response); None when the
    baseline has none."""
    i = low_pass_index(model)
    if i is None:
        return None
    p = model.effects[i].params
    sigma, tau0, floor = float(p["sigma_dph"]), 1.0 / float(model.sample_rate_hz), float(model.noise.N_dpsh)
    out = {"kind": model.effects[i].kind, "sigma_dph": sigma, "floor_N_dpsh": floor}
    if out["kind"] == "markov":
        tau_c = float(p["tau_c_s"])
        a = math.exp(-tau0 / tau_c)
        out.update(order=1, corner_hz=1.0 / (2.0 * math.pi * tau_c), tau_c_s=tau_c)
        psd0 = sigma ** 2 * (1.0 + a) / (1.0 - a)
    else:
        h = lowpass_impulse(p["cutoff_hz"], p["order"], model.sample_rate_hz)
        out.update(order=int(p["order"]), corner_hz=float(p["cutoff_hz"]), tau_c_s=None)
        psd0 = sigma ** 2 / float(np.sum(h * h))
    return {**out, "white_N_dpsh": math.sqrt(psd0 * tau0 / 3600.0 + floor ** 2)}


def low_pass_text(lp: dict) -> str:
    """The baseline's low-pass (:func:`baseline_low_pass`) in words, with units."""
    floor = (f", beside unfiltered white noise N {lp['floor_N_dpsh']:.4g} deg/sqrt(h)" if lp["floor_N_dpsh"] > 0
             else "")
    if lp["kind"] == "markov":
        shape = (f"white noise through a first-order low-pass, corner {lp['corner_hz']:.3g} Hz (a Gauss-Markov "
                 f"term, sigma {lp['sigma_dph']:.4g} deg/h, tau_c {lp['tau_c_s']:.3g} s")
    else:
        shape = (f"white noise through a Butterworth low-pass of order {lp['order']}, cutoff "
                 f"{lp['corner_hz']:.3g} Hz (sigma {lp['sigma_dph']:.4g} deg/h")
    return f"{shape}{floor}; N {lp['white_N_dpsh']:.4g} deg/sqrt(h) at longer taus)"


def _baseline_text(res: Result) -> str:
    """How the baseline was fitted, one sentence (empty with a model)."""
    if not res.baseline:
        return ""
    lp = baseline_low_pass(res.model)
    if lp is None:
        return ""
    return (f"The recording's ADEV bends below the white-noise slope at the shortest taus (the sensor's own "
            f"low-pass), so the baseline holds {low_pass_text(lp)}, fitted with the IEEE-952 terms before any "
            f"effect was judged.")


def verdict(res: Result, mism: list[dict], mism_after: list[dict]) -> str:
    """One paragraph a gyro engineer can act on."""
    base = _baseline_text(res)
    text = _verdict(res, mism, mism_after)
    return f"{text} {base}" if base else text


def _verdict(res: Result, mism: list[dict], mism_after: list[dict]) -> str:
    sb, sa = res.before.score.value, res.after.score.value
    ref = "the baseline stationary model fitted from the recording" if res.baseline else "the model"
    if not res.accepted and not mism:
        none = (f"no (time, tau) cell lies beyond the {100 * res.before.null.alpha:g} % family-wise threshold "
                f"and no candidate effect passes BIC and a held-out check and lowers the score")
        if sb <= CHANCE_SCORE:
            return f"{ref[0].upper() + ref[1:]} explains the recording: {none} (score {sb:.2f}, about 1 = chance)."
        comp = res.before.score.as_json()
        top = max(comp, key=comp.__getitem__)
        return (f"Against {ref}, {none}; yet the score is {sb:.2f}, above chance (about 1; its largest figure: "
                f"{top} {comp[top]:.2f}): the recording departs from it in a way no effect fogmon knows explains.")
    parts = []
    if mism:
        parts.append(f"Against {ref} the recording shows {len(mism)} mismatch region(s) "
                     f"(strongest: {_region_text(mism[0])}); score {sb:.2f}.")
    else:
        parts.append(f"Against {ref} the dynamic Allan deviation shows no region beyond the threshold, "
                     f"but matched tests do (score {sb:.2f}).")
    if res.accepted:
        parts.append("Missing physics, in order of importance: "
                     + "; ".join(effect_summary(a.cand.kind, a.cand.params, _model_noise(res))
                                 for a in res.accepted) + ".")
        unexplained = [m for m in mism_after if not m.get("nonstationary")]
        bursts = len(mism_after) - len(unexplained)
        named = (f" ({bursts} more left are non-stationary bursts named in the warnings, not missing physics)"
                 if bursts else "")
        if sa <= CHANCE_SCORE and not unexplained:
            parts.append(f"With these added the recording is within chance (score {sa:.2f}, no mismatch left"
                         f"{named}): add them to the sensor model (--out-model) or remove the deterministic "
                         f"ones from the data (--out-corrected).")
        elif not unexplained:
            parts.append(f"With these added the score is {sa:.2f}; the {bursts} region(s) left are non-stationary "
                         f"bursts named in the warnings (band-limited rms far above the rest of the record), "
                         f"not missing physics: no stationary effect kind models them.")
        else:
            left = f"; strongest left: {_region_text(unexplained[0])}"
            parts.append(f"With these added the score is {sa:.2f} and {len(unexplained)} region(s) remain{left}"
                         f"{named}: the catalogue does not explain everything - inspect those times and taus.")
    else:
        parts.append("No catalogued effect passes BIC and the held-out check and lowers the score; the "
                     "mismatch may come from "
                     "wrong noise coefficients or from physics outside the catalogue.")
    hint = _line_hint(res, mism_after if res.accepted else mism)
    if hint:
        parts.append(hint)
    return " ".join(parts)


def _line_hint(res: Result, left: list[dict]) -> str:
    """For an excess no accepted effect explains: narrowband lines in the residual at the
    frequencies that tau band responds to (a sinusoid of frequency f peaks in the ADEV
    at tau = 0.371 / f), e.g. vehicle sway or drill-string vibration that is not one
    coherent sinusoid over the record (so `periodic` cannot model it)."""
    excess = [r for r in left if r["sign"] == "excess" and not r.get("nonstationary")]
    if not excess:
        return ""
    r = excess[0]
    sample_rate_hz = res.grid.sample_rate_hz
    lines = spectral_lines(res.residual_after, sample_rate_hz,
                           *tau_band_hz(r["tau_min_s"], r["tau_max_s"], sample_rate_hz))
    if not lines:
        return ""
    where = ", ".join(f"{f:.3g} Hz ({ratio:.0f}x the band median)" for f, ratio in lines)
    why = next((w for k, _, w in res.rejected if k == "vibration_lines"), None)
    fit = (f"the vibration_lines fit was refused: {why}" if why else
           "the vibration_lines fit does not account for it")
    return (f"The unexplained excess at tau {r['tau_min_s']:.3g}..{r['tau_max_s']:.3g} s goes with narrowband "
            f"power in the residual at {where}: vibration or platform motion that is not one coherent "
            f"sinusoid over the record ({fit}); check the mounting and the "
            f"vibration environment at those frequencies.")


def outliers_path(report_path: str) -> str:
    """The file next to the report that lists every outlier (REPORT.outliers.csv)."""
    return os.path.splitext(report_path)[0] + ".outliers.csv"


def build_report(res: Result, recording_path: str, model_path: str | None, times_file: str = "") -> dict:
    """The report (docs/formats.md, explain report); ``times_file`` names the outliers file relative
    to the report (an ``outliers`` effect's ``times_file`` parameter)."""
    mism = [r.as_json() for r in res.before.regions]
    mism_after = [{**r.as_json(), "nonstationary": any(r is x for x in res.nonstationary)}
                  for r in res.after.regions]
    effects = []
    for a in res.accepted:
        c = a.cand
        params = dict(c.params) if c.corrected_noise is not None else dict(c.effect().params)
        if c.kind == "outliers":
            params["times_file"] = times_file
        effects.append({"kind": c.kind, "params": params, "uncertainty": c.se, "evidence": c.evidence,
                        "heldout": a.heldout, "bic_gain": round(a.bic_gain, 2),
                        "score_before": round(a.score_before, 3), "score_after": round(a.score_after, 3)})
        if c.corrected_noise is not None:
            effects[-1]["model_noise"] = {k: v for k, v in _model_noise(res).items() if k in params}
    g = res.grid
    rep = {
        "recording": recording_path,
        "model": model_path if model_path else "baseline: stationary IEEE-952 model fitted from the recording",
        "mismatches": mism,
        "effects": effects,
        "score_before": round(res.before.score.value, 3),
        "score_after": round(res.after.score.value, 3),
        "verdict": verdict(res, mism, mism_after),
        "warnings": res.warnings,
        "mismatches_after": mism_after,
        "score_components_before": res.before.score.as_json(),
        "score_components_after": res.after.score.as_json(),
        "refused": [{"kind": k, "bic_gain": round(b, 2), "why": why} for k, b, why in res.rejected],
        "method": {
            "sample_rate_hz": g.sample_rate_hz,
            "n_samples": g.n,
            "window_s": g.window_s,
            "hop_s": g.hop_n / g.sample_rate_hz,
            "n_windows": len(g.starts),
            "taus_s": g.tau_s.tolist(),
            "n_bootstrap": res.n_boot,
            "family_wise_alpha": res.before.null.alpha,
            "threshold_abs_z": round(res.before.null.threshold, 3),
            "threshold_abs_z_whole_record": round(res.before.null.threshold_whole, 3),
        },
    }
    rep["record_fit"] = res.record_fit if res.record_fit is not None else record_fit(res.recording)
    if res.baseline:
        nz = res.model.noise
        rep["baseline_model"] = {"bias_dph": res.model.bias_dph, "Q_arcsec": nz.Q_arcsec, "N_dpsh": nz.N_dpsh,
                                 "B_dph": nz.B_dph, "K_dphsh": nz.K_dphsh, "R_dphh": nz.R_dphh,
                                 "low_pass": baseline_low_pass(res.model)}
    return json_safe(rep)


def record_fit(rec, keep_motion: bool = False) -> dict | None:
    """The record's own IEEE-952 coefficients exactly as ``fogmon replay`` prints them for
    the recording ``rec`` as recorded (before explain keeps its platform motion out):
    ``davar.record.whole_record_fit`` of the rate, or its error against rot_dps, on the
    octave taus, over the latest ``pipeline.OVERALL_MAX_SAMPLES`` samples, with the samples
    the live motion gate judges moving left out (``motion_gate.gate_record``, the replay's
    gate; none with ``keep_motion``, as ``--keep-motion``). Explain's own analysis keeps
    out what the offline ``find_motion`` finds, bursts too (docs/motion.md), so its
    ``platform_motion`` warnings can name more. Per coefficient ``value`` (0 when not
    identifiable), ``lo``/``hi`` (the interval at ``confidence``; [0, upper] when not
    identifiable), ``identifiable``, ``upper`` (one-sided 95 % upper limit); ``q_is``
    "quantization" or "white angle noise" (``NoiseFit.q_band_limited``), ``contradicted``
    (the terms the measured ADEV refutes: name, the fit's value, tau_s, the term's and the
    measured ADEV and its upper bound, deg/h, the ADEV's limit on the term),
    ``motion_samples`` (kept out by the gate). Not the baseline model, which is explain's
    null (docs/explain.md, "The baseline and the record's fit"); None when the record is
    too short for a whole-record ADEV."""
    from fogmon.davar.record import whole_record_fit
    from fogmon.errors import FogmonError
    from fogmon.motion_gate import gate_record
    from fogmon.pipeline import OVERALL_MAX_SAMPLES

    blk = rec.to_block()
    y = blk.error_rate_dph
    valid = blk.valid & np.isfinite(y)
    gated = valid if keep_motion else gate_record(y, rec.sample_rate_hz, valid).valid
    tail = slice(max(0, len(y) - OVERALL_MAX_SAMPLES), len(y))
    try:
        _, fit = whole_record_fit(y[tail], gated[tail], rec.sample_rate_hz)
    except FogmonError:
        return None
    out: dict = {"taus": "octave", "confidence": fit.confidence}
    for name, c in fit.coefficients().items():
        out[name] = {"value": float(c.value), "lo": float(c.lo), "hi": float(c.hi),
                     "identifiable": bool(c.identifiable), "upper": float(c.upper)}
    out["q_is"] = "white angle noise" if fit.q_band_limited else "quantization"
    out["contradicted"] = [{"name": c.name, "value": c.value, "tau_s": c.tau_s, "term_adev_dph": c.term_adev_dph,
                            "adev_dph": c.adev_dph, "bound_dph": c.bound_dph, "limit": c.limit}
                           for c in fit.contradicted]
    out["motion_samples"] = int(np.count_nonzero(valid[tail] & ~gated[tail]))
    return out


def record_fit_text(rf: dict) -> str:
    """The record's fit (:func:`record_fit`) on one line, with units."""
    from fogmon.units import coefficient_unit

    cells = []
    for name in ("Q_arcsec", "N_dpsh", "B_dph", "K_dphsh", "R_dphh"):
        c, unit = rf[name], coefficient_unit(name)
        short = name.split("_")[0]
        if c["identifiable"]:
            cells.append(f"{short} {c['value']:.4g} [{c['lo']:.4g}, {c['hi']:.4g}] {unit}")
        elif c["upper"] is not None:
            cells.append(f"{short} < {c['upper']:.4g} {unit}")
    q = " (Q: white angle noise, not quantization)" if rf["q_is"] != "quantization" else ""
    refuted = "".join(f"; {c['name']} {c['value']:.4g} refuted by the ADEV at {c['tau_s']:.4g} s"
                      for c in rf["contradicted"] if c["name"] != "Q_arcsec")
    moved = rf.get("motion_samples", 0)
    gate = f", {moved} samples of platform motion kept out by its gate" if moved else ""
    return (f"record's IEEE-952 fit (as fogmon replay prints it{gate}; {100 * rf['confidence']:.1f} % intervals, "
            f"'<': 95 % upper limits): {'; '.join(cells)}{q}{refuted}")


def write_report(rep: dict, path: str) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(rep, fh, indent=2)
        fh.write("\n")


def console_summary(rep: dict) -> str:
    """A few lines for the terminal."""
    lines = [f"fogmon explain: {os.path.basename(rep['recording'])} vs {rep['model']}",
             f"  score before {rep['score_before']:.2f} -> after {rep['score_after']:.2f} (about 1 = chance)",
             f"  mismatch regions: {len(rep['mismatches'])} before, {len(rep['mismatches_after'])} after"]
    lp = (rep.get("baseline_model") or {}).get("low_pass")
    if lp:
        lines.insert(1, f"  baseline: {low_pass_text(lp)}")
    bm = rep.get("baseline_model")
    if bm:
        from fogmon.units import coefficient_unit

        terms = ", ".join(f"{n.split('_')[0]} {bm[n]:.4g} {coefficient_unit(n)}"
                          for n in ("Q_arcsec", "N_dpsh", "B_dph", "K_dphsh", "R_dphh") if bm[n])
        lines.insert(1, f"  baseline model (explain's null, robust to effects: window medians, R = 0; not the "
                        f"record's fit): {terms or 'no IEEE-952 term'}")
    if rep.get("record_fit"):
        lines.insert(1, f"  {record_fit_text(rep['record_fit'])}")
    for r in rep["mismatches"][:5]:
        lines.append("    - " + _region_text(r))
    if len(rep["mismatches"]) > 5:
        lines.append(f"    ... and {len(rep['mismatches']) - 5} more in the report")
    if rep["effects"]:
        lines.append("  effects added:")
        for e in rep["effects"]:
            lines.append(f"    + {effect_summary(e['kind'], e['params'], e.get('model_noise'))} "
                         f"(score {e['score_before']:.2f} -> {e['score_after']:.2f})")
    else:
        lines.append("  effects added: none")
    for w in rep["warnings"]:
        lines.append(f"  warning {w['kind']}: {w['text']}")
    lines.append("  verdict: " + rep["verdict"])
    return "\n".join(lines)


def write_outliers(res: Result, path: str) -> int:
    """Every outlier of an accepted ``outliers`` effect as CSV (time_s in s, amplitude_dph
    = the spike removed in deg/h, abs_z = its robust spike-test |z|) under a commented
    header, then every spike a ``spikes`` warning names (``Result.spikes``: left in the
    final residual, not removed); without an outliers effect those spikes alone; nothing
    is written when there is neither. Returns the rows written."""
    held = [a.cand for a in res.accepted if a.cand.kind == "outliers"]
    if held:
        lst = held[0].listing
        assert lst is not None, "an outliers candidate carries its listing"
        what = f"{len(lst['times_s'])} outlier samples"
        amp = "the spike removed (deg/h)"
        if res.spikes is not None:   # left after the population: listed after its outliers
            left = len(res.spikes["times_s"])
            what = (f"{len(lst['times_s'])} outlier samples, then the {left} spike(s) the final residual still "
                    f"holds beyond a Gaussian noise's 1 % family-wise spike threshold (not removed; the spikes "
                    f"warning)")
            lst = {k: np.concatenate([lst[k], res.spikes[k]]) for k in ("times_s", "amplitudes_dph", "abs_z")}
            amp += " or, for the spikes left, its GLS amplitude (deg/h)"
    elif res.spikes is not None:  # more than chance, no outlier effect: the `spikes` warning's list
        lst, amp = res.spikes, "the spike's GLS amplitude (deg/h), not removed"
        after = any(a.cand.kind == "glitches" for a in res.accepted)
        what = (f"{len(lst['times_s'])} spikes " + ("the final residual still holds " if after else "")
                + "beyond a Gaussian noise's 1 % family-wise spike threshold"
                + (" after the glitches" if after else ", no effect accepted"))
    else:
        _remove_stale_outliers(path)
        return 0
    n = len(lst["times_s"])
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(f"# fogmon explain outliers of {res.recording.name}: all {what} (none left out)\n"
                 f"# amplitude_dph: {amp}; abs_z: its robust spike-test |z|\n"
                 "time_s,amplitude_dph,abs_z\n")
        for t, a, z in zip(lst["times_s"].tolist(), lst["amplitudes_dph"].tolist(), lst["abs_z"].tolist(), strict=True):
            fh.write(f"{t!r},{a:.9g},{z:.4g}\n")
    return n


def _remove_stale_outliers(path: str) -> None:
    """Remove an outliers file an earlier run left next to the report (recognised by its
    first line), so that it is never read as this run's."""
    try:
        with open(path, encoding="utf-8") as fh:
            ours = fh.readline().startswith("# fogmon explain outliers of ")
    except (OSError, UnicodeDecodeError):
        return
    if ours:
        os.remove(path)


def write_outputs(res: Result, out_model: str | None, out_corrected: str | None,
                  outliers_file: str | None = None) -> None:
    """--out-model (fitted model TOML; an ``outliers`` effect names ``outliers_file``
    relative to the model; a ``noise`` effect's corrections are in its [noise]) and
    --out-corrected (recording minus the fitted deterministic effects and the Wiener
    estimate of any vibration_lines, outliers replaced, replay log v1, same samples and
    aux columns)."""
    if out_model:
        fitted = res.fitted
        if outliers_file:
            rel = os.path.relpath(outliers_file, os.path.dirname(os.path.abspath(out_model)))
            fitted = replace(fitted, effects=[Effect(e.kind, {**e.params, "times_file": rel})
                                              if e.kind == "outliers" else e for e in fitted.effects])
        save_model(fitted, out_model)
    if out_corrected:
        rec = res.recording
        meta = {**rec.meta, "sample_rate_hz": f"{rec.sample_rate_hz:g}", **corrected_meta(res)}
        write_replay_log(out_corrected, rec.t_s, corrected_rate_dph(res), rec.aux, meta)


def corrected_rate_dph(res: Result) -> np.ndarray:
    """The rate (deg/h) of each sample of ``res.recording`` minus the fitted deterministic
    effects (``Result.deterministic_fit``: vibration_lines' Wiener estimate, outliers'
    replacements included)."""
    return res.recording.rate_dph - res.deterministic_fit[res.recording.grid_index()]


def corrected_meta(res: Result, suffix: str = "") -> dict[str, str]:
    """The metadata lines of --out-corrected that say what was removed:
    ``corrected_by<suffix>`` and, with an outliers population, ``outliers_replaced<suffix>``."""
    meta = {f"corrected_by{suffix}": "fogmon explain: " + (", ".join(
        a.cand.kind + (" (Wiener estimate of the line signal)" if a.cand.kind == "vibration_lines" else "")
        for a in res.accepted if a.cand.rate is not None) or "nothing")}
    for a in res.accepted:
        if a.cand.kind == "outliers":
            meta[f"outliers_replaced{suffix}"] = (f"{a.cand.params['count']} samples (listed in the outliers file "
                                                  f"next to the report): interpolation from their neighbours plus "
                                                  f"the model's conditional noise")
    return meta


def _adev_band(a, null, sample_rate_hz):
    """Whole-record ADEV (deg/h): null mean, family-wise band, recording."""
    infl = math.sqrt(1 + 1 / null.n_replicates)
    thr = null.threshold_whole
    lo_u = np.maximum(null.mu_u_whole - thr * null.sd_whole * infl, 1e-6)
    hi_u = null.mu_u_whole + thr * null.sd_whole * infl
    return (np.exp(null.mu_whole / 2), np.exp(null.mu_whole / 2) * lo_u ** 1.5,
            np.exp(null.mu_whole / 2) * hi_u ** 1.5, np.exp(a.whole / 2))


def write_png(res: Result, path: str) -> None:
    """Four panels: whole-record ADEV with bootstrap bands before/after, z-map before and
    after with the flagged regions outlined, residual with the fitted effects."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = res.grid
    fig, ax = plt.subplots(2, 2, figsize=(13, 9), constrained_layout=True)
    tau = g.tau_whole_s
    for a, label, col in ((res.before, "before", "tab:red"), (res.after, "after", "tab:blue")):
        med, lo, hi, rec = _adev_band(a, a.null, g.sample_rate_hz)
        ax[0, 0].fill_between(tau, lo, hi, color=col, alpha=0.15,
                              label=f"model {label}: {100 * (1 - a.null.alpha):g} % family-wise band")
        ax[0, 0].loglog(tau, med, color=col, lw=1, ls="--")
        ax[0, 0].loglog(tau, rec, "o-", color=col, ms=3, label=f"recording residual ({label})")
    ax[0, 0].set_xlabel("tau (s)")
    ax[0, 0].set_ylabel("Allan deviation of the residual (deg/h)")
    ax[0, 0].legend(fontsize=7)
    ax[0, 0].set_title(f"whole record: score {res.before.score.value:.2f} -> {res.after.score.value:.2f}")
    tc = g.t_centre_s
    lim = max(3.0, float(np.nanmax(np.abs(res.before.z))) if np.isfinite(res.before.z).any() else 3.0)
    for axx, a, label in ((ax[0, 1], res.before, "before"), (ax[1, 0], res.after, "after")):
        im = axx.pcolormesh(tc, np.log10(g.tau_s), a.z.T, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="nearest")
        for r in a.regions:
            if r.whole_record:
                continue
            axx.add_patch(plt.Rectangle((r.t_start_s, math.log10(r.tau_min_s) - 0.15),
                                        r.t_end_s - r.t_start_s, math.log10(r.tau_max_s / r.tau_min_s) + 0.3,
                                        fill=False, ec="k", lw=1.2))
        axx.set_xlabel("window centre time (s)")
        axx.set_ylabel("log10 tau (s)")
        axx.set_title(f"z-map {label} (|z| > {a.null.threshold:.2f} flagged, {len(a.regions)} region(s))")
        fig.colorbar(im, ax=axx, label="z of Allan variance (cube-root scale)")
    t = res.t_s
    step = max(1, len(t) // 4000)
    k = max(1, step)
    y = np.where(res.valid, res.residual_before, np.nan)
    nb = len(y) // k
    with warnings.catch_warnings():          # stretches with no valid sample (gaps, platform motion)
        warnings.simplefilter("ignore", RuntimeWarning)
        ym = np.nanmean(y[: nb * k].reshape(nb, k), axis=1)
    ax[1, 1].plot(t[: nb * k: k], ym, lw=0.5, color="0.5", label=f"residual vs model ({k}-sample means)")
    det = res.deterministic_fit
    ax[1, 1].plot(t[: nb * k: k], det[: nb * k].reshape(nb, k).mean(axis=1), color="tab:orange", lw=1.2,
                  label="fitted deterministic effects")
    ax[1, 1].set_xlabel("time (s)")
    ax[1, 1].set_ylabel("rate (deg/h)")
    ax[1, 1].legend(fontsize=7)
    ax[1, 1].set_title("fitted effects over the data")
    fig.savefig(path, dpi=90)
    plt.close(fig)


#: Colours of the explain .rrd's ADEV plot: before / after the fitted effects.
_RRD_COLOURS = {"before": ((230, 80, 70), (190, 110, 100)), "after": ((80, 150, 255), (100, 140, 200))}


def write_rrd(res: Result, path: str) -> None:
    """The same evidence in a Rerun recording with its layout (blueprint): the
    whole-record ADEV of the residual with the model's family-wise band before and after
    (log-log, labelled, ``adev``), the z-maps as labelled heatmaps with a colour scale
    and the flagged regions outlined (``zmap_before``, ``zmap_after``), residual and
    fitted effects over time (``rate``, timeline ``time``) and the verdict. Everything but
    ``rate`` is static, so it shows whatever the time cursor."""
    import rerun as rr

    adev = rrd_adev_logs(res)
    rec = rr.RecordingStream("fogmon_explain")
    rec.save(path, default_blueprint=rrd_blueprint(adev[2], adev[3]))
    log_rrd(rec, res, adev)
    rec.flush()


def log_rrd(rec, res: Result, adev, prefix: str = "") -> None:
    """Log the evidence of ``write_rrd`` into the Rerun stream ``rec``, every entity under
    ``prefix`` (``""``, or ``axis/<name>/`` for one axis of several); ``adev`` is
    ``rrd_adev_logs(res)``."""
    import rerun as rr

    g = res.grid
    lx, logs, x_dec, y_dec = adev
    _rrd_adev(rec, res, lx, logs, x_dec, y_dec, prefix)
    lim = max(3.0, float(np.nanmax(np.abs(res.before.z))) if np.isfinite(res.before.z).any() else 3.0)
    for a, label in ((res.before, "before"), (res.after, "after")):
        _rrd_zmap(rec, f"{prefix}zmap_{label}", a, g, lim)
    t = res.t_s
    k = max(1, len(t) // 20000)
    nb = len(t) // k
    y = np.where(res.valid, res.residual_before, np.nan)[: nb * k].reshape(nb, k)
    det = res.deterministic_fit[: nb * k].reshape(nb, k)
    rec.log(f"{prefix}rate", rr.SeriesLines(names=["residual vs model (deg/h)",
                                                   "fitted deterministic effects (deg/h)"],
                                            colors=[(170, 170, 170), (255, 170, 0)], widths=[0.7, 1.5]), static=True)
    with warnings.catch_warnings():          # stretches with no valid sample (gaps, platform motion)
        warnings.simplefilter("ignore", RuntimeWarning)
        ym = np.nanmean(y, axis=1)
    rec.send_columns(f"{prefix}rate", indexes=[rr.TimeColumn("time", duration=t[: nb * k: k])],
                     columns=rr.Scalars.columns(scalars=np.column_stack([ym, det.mean(axis=1)])))
    for acc in res.accepted:
        if acc.cand.kind == "outliers":  # every outlier, as points over time
            lst = acc.cand.listing
            assert lst is not None, "an outliers candidate carries its listing"
            rec.log(f"{prefix}rate/outliers_removed_dph", rr.SeriesPoints(names=["outlier amplitude removed (deg/h)"]),
                    static=True)
            rec.send_columns(f"{prefix}rate/outliers_removed_dph",
                             indexes=[rr.TimeColumn("time", duration=lst["times_s"])],
                             columns=rr.Scalars.columns(scalars=lst["amplitudes_dph"]))
    rec.log(f"{prefix}verdict", rr.TextDocument(verdict(res, [r.as_json() for r in res.before.regions],
                                                        [r.as_json() for r in res.after.regions])), static=True)


def rrd_blueprint(x_dec: tuple[int, int], y_dec: tuple[int, int]):
    """The explain .rrd's layout (``rrd_layout``) with the time panel collapsed."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(rrd_layout(x_dec, y_dec), rrb.TimePanel(timeline="time", state="collapsed"),
                         collapse_panels=True)


def rrd_layout(x_dec: tuple[int, int], y_dec: tuple[int, int], prefix: str = "", name: str | None = None):
    """The views of one explain: ADEV plot (framing decades ``x_dec`` of tau in s and
    ``y_dec`` of ADEV in deg/h) and verdict | z-maps before and after | residual over
    time, of the entities under ``prefix`` (``log_rrd``), the container called ``name``."""
    import rerun as rr
    import rerun.blueprint as rrb

    from fogmon.sinks.rerun.plots import heatmap_bounds, loglog_bounds

    whole = rr.TimeRange(start=rr.TimeRangeBoundary.infinite(), end=rr.TimeRangeBoundary.infinite())
    return rrb.Vertical(
        rrb.Horizontal(rrb.Spatial2DView(origin=f"/{prefix}adev", name="Whole record: ADEV of the residual (deg/h) "
                                         "vs tau (s), log-log, with the model's family-wise band",
                                         visual_bounds=loglog_bounds(x_dec, y_dec)),
                       rrb.TextDocumentView(origin=f"/{prefix}verdict", name="Verdict"), column_shares=[2, 1]),
        rrb.Horizontal(*(rrb.Spatial2DView(origin=f"/{prefix}zmap_{w}", name=f"z-map {w} the fitted effects: z by "
                                           f"tau (s, rows) and window centre time (s, columns)",
                                           visual_bounds=heatmap_bounds())
                         for w in ("before", "after"))),
        rrb.TimeSeriesView(origin=f"/{prefix}rate", name="Residual vs model and fitted effects (deg/h) over time (s)",
                           axis_x=rrb.TimeAxis(view_range=whole)),
        row_shares=[1.3, 1.2, 1], name=name)


def rrd_adev_logs(res: Result):
    """(log10 tau, {"before"/"after": log10 of (model median, band lo, band hi, recording
    residual ADEV)}, decades of tau, decades of ADEV) of the whole-record ADEV plot."""
    g = res.grid
    lx = np.log10(g.tau_whole_s)
    curves = {w: _adev_band(a, a.null, g.sample_rate_hz) for w, a in (("before", res.before), ("after", res.after))}
    with np.errstate(divide="ignore", invalid="ignore"):
        logs = {w: [np.log10(c) for c in cs] for w, cs in curves.items()}
    fin = np.concatenate([v[np.isfinite(v)] for cs in logs.values() for v in cs])
    x_dec = (math.floor(lx.min()), math.ceil(lx.max()))
    y_dec = (math.floor(fin.min()), math.ceil(fin.max())) if fin.size else (-1, 1)
    return lx, logs, x_dec, y_dec


def _rrd_adev(rec, res: Result, lx, logs, x_dec, y_dec, prefix: str = "") -> None:
    """The whole-record ADEV (``rrd_adev_logs``) of the residual, the model's median and
    family-wise band, before and after, on a labelled log-log plot with a legend."""
    import rerun as rr

    from fogmon.sinks.rerun import plots as rp

    ent = f"{prefix}adev/log10"
    rec.log(ent, rp.loglog_transform(), static=True)
    rp.log_decade_grid(rec, ent, x_dec, y_dec, "s", "deg/h")
    items = []
    for w, (med, lo, hi, r) in logs.items():
        bright, dim = _RRD_COLOURS[w]
        ok = np.isfinite(r)
        pts = np.column_stack([lx[ok], r[ok]])
        rec.log(f"{ent}/{w}/recording_residual",
                rr.LineStrips2D([pts], colors=[bright], radii=rr.Radius.ui_points(1.5)),
                rr.Points2D(pts, colors=[bright], radii=rr.Radius.ui_points(3.0)), static=True)
        m = np.isfinite(med)
        rec.log(f"{ent}/{w}/model_median", rr.LineStrips2D([np.column_stack([lx[m], med[m]])], colors=[dim],
                                                            radii=rr.Radius.ui_points(1.0)), static=True)
        b = np.isfinite(lo) & np.isfinite(hi)
        edges = [np.column_stack([lx[b], lo[b]]), np.column_stack([lx[b], hi[b]])]
        rec.log(f"{ent}/{w}/model_band", rr.LineStrips2D(edges, colors=[dim], radii=rr.Radius.ui_points(0.7)),
                static=True)
        rp.log_band_bars(rec, f"{ent}/{w}/model_band/bars", lx, lo, hi, dim, dx=-0.03 if w == "before" else 0.03)
        band = f"{100 * (1 - getattr(res, w).null.alpha):g} % family-wise band"
        items += [(f"recording residual {w} the effects", bright), (f"model {w}: median and {band}", dim)]
    rp.log_loglog_legend(rec, f"{ent}/legend", items, x_dec, y_dec)
    rp.log_tau_spans(rec, f"{ent}/whole_record_regions", [
        (r.tau_min_s, r.tau_max_s, f"{w}: whole record, ADEV x{r.ratio:.2f}, |z| {r.max_abs_z:.1f}")
        for w in ("before", "after") for r in getattr(res, w).regions if r.whole_record], y_dec, (255, 210, 0))


def _rrd_zmap(rec, ent: str, a, g, lim: float) -> None:
    """A z-map (z of the Allan variance, windows x taus) as a labelled heatmap: rows tau
    (largest on top), columns windows (centre time), colour scale -lim..lim, the flagged
    regions outlined."""
    import rerun as rr

    from fogmon.sinks.rerun import plots as rp

    z = np.asarray(a.z, dtype=np.float64).T[::-1]          # rows: largest tau on top
    n_rows, n_cols = z.shape
    tau, tc = g.tau_s, g.t_centre_s
    rows = rp.decade_rows(tau)
    cols = np.unique(np.linspace(0, n_cols - 1, min(n_cols, 5)).round().astype(int))
    ticks = rp.nice_ticks(-lim, lim)
    rp.log_heatmap(rec, ent, z, -lim, lim, "RdBu_r",
                   ([n_rows - 1 - i for i in rows], [f"{tau[i]:.3g} s" for i in rows]),
                   (cols, [f"{tc[c]:.6g} s" for c in cols]), (ticks, [f"z = {v:g}" for v in ticks]), static=True)
    boxes = []
    for r in a.regions:
        if r.whole_record or not r.cells:
            continue
        w = np.array([c[0] for c in r.cells])
        rows_r = n_rows - 1 - np.array([c[1] for c in r.cells])
        x0, x1, y0, y1 = w.min(), w.max() + 1, rows_r.min(), rows_r.max() + 1
        boxes.append([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
    if whole := [r for r in a.regions if r.whole_record]:   # not tied to a time: boxed on the ADEV plot
        taus = ", ".join(f"{r.tau_min_s:g}" + (f"..{r.tau_max_s:g}" if r.tau_max_s > r.tau_min_s else "")
                         for r in whole)
        rp.log_heatmap_note(rec, ent, f"+ whole-record mismatch at tau {taus} s: boxed on the ADEV plot", (255, 210, 0))
    if boxes:                                              # in the image's pixels (log_heatmap's map)
        rec.log(f"{ent}/map/regions", rr.LineStrips2D(boxes, colors=[(0, 0, 0)], radii=rr.Radius.ui_points(1.5)),
                static=True)
