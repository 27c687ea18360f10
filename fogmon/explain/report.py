"""Outputs of `fogmon explain`: the JSON report (CONTRACT section 4, plus extra keys),
a console summary, a PNG of the evidence and an optional Rerun .rrd with the same.

Extra report keys beyond the contract (added, never renamed): ``mismatches_after``,
per-region ``tau_peak_s`` and ``windows_span_s``,
``score_components_before/after``, per-effect ``uncertainty``, ``heldout``,
``bic_gain``, per ``noise`` effect ``model_noise`` (the model's values it corrects),
``refused`` candidates and ``method`` (window, hop, taus, bootstrap size,
family-wise threshold)."""
from __future__ import annotations

import json
import math
import os
import warnings

import numpy as np

from fogmon.explain.catalogue import NOISE_UNIT, noise_text
from fogmon.explain.detectors import spectral_lines
from fogmon.explain.explainer import Result
from fogmon.recording import write_replay_log
from fogmon.sim.model import save_model


def _clean(x):
    """JSON-safe plain Python numbers (NaN/inf -> None)."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
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


def _effect_summary(kind: str, p: dict, model: dict | None = None) -> str:
    """One phrase with the numbers of an effect (``model``: the model's [noise] values,
    for the ``noise`` kind)."""
    if kind == "periodic":
        return f"periodic {p['amplitude_dph']:.3g} deg/h at period {p['period_s']:.5g} s"
    if kind == "bias_step":
        return f"bias step {p['step_dph']:+.3g} deg/h at t = {p['t_s']:.6g} s"
    if kind == "rate_ramp":
        return f"rate ramp {p['slope_dphh']:+.3g} deg/h^2 from t = {p['t0_s']:.6g} s"
    if kind == "warm_up":
        return f"warm-up {p['amplitude_dph']:+.3g} deg/h settling with tau = {p['tau_s']:.4g} s"
    if kind == "glitches":
        return f"{len(p['times_s'])} glitch(es)"
    if kind == "scale_factor":
        return f"scale-factor error {p['ppm']:.3g} ppm (asymmetry {p['asym_ppm']:.3g} ppm)"
    if kind == "thermal_drift":
        return (f"thermal drift (K1 {p['k1_pos']:.3g}/{p['k1_neg']:.3g} deg/h per degC/s, "
                f"K0 slope {p['k0_poly_dph'][1] if len(p['k0_poly_dph']) > 1 else 0:.3g} deg/h/degC)")
    if kind == "markov":
        return f"Gauss-Markov noise {p['sigma_dph']:.3g} deg/h, correlation time {p['tau_c_s']:.4g} s"
    if kind == "vibration_noise":
        return f"vibration-driven ARW {p['n_gain_dpsh_per_g']:.3g} deg/sqrt(h) per g"
    if kind == "temperature_noise":
        return f"temperature-driven ARW {p['n_gain_dpsh_per_c']:.3g} deg/sqrt(h) per degC (ref {p['t_ref_c']:.3g} degC)"
    if kind == "bandwidth":
        return f"sensor low-pass: Butterworth order {p['order']} at {p['cutoff_hz']:.4g} Hz"
    if kind == "vibration_lines":
        return "narrowband vibration " + ", ".join(
            f"{f:.4g} Hz (bandwidth {bw:.3g} Hz, rms {sg:.3g} deg/h)"
            for f, sg, bw in zip(p["freq_hz"], p["sigma_dph"], p["bandwidth_hz"]))
    if kind == "noise":
        return "wrong noise coefficients: " + "; ".join(
            noise_text(k, p[k], p[f"{k}_lo"], p[f"{k}_hi"], model[k]) for k in NOISE_UNIT if k in p)
    return kind


def _model_noise(res: Result) -> dict:
    nz = res.model.noise
    return {k: getattr(nz, k) for k in NOISE_UNIT}


def verdict(res: Result, mism: list[dict], mism_after: list[dict]) -> str:
    """One paragraph a gyro engineer can act on."""
    sb, sa = res.before.score.value, res.after.score.value
    ref = "the baseline stationary model fitted from the recording" if res.baseline else "the model"
    if not res.accepted and not mism:
        return (f"{ref[0].upper() + ref[1:]} explains the recording: no (time, tau) cell lies beyond the "
                f"{100 * res.before.null.alpha:g} % family-wise threshold and no candidate effect passes "
                f"BIC and a held-out check and lowers the score (score {sb:.2f}, about 1 = chance).")
    parts = []
    if mism:
        parts.append(f"Against {ref} the recording shows {len(mism)} mismatch region(s) "
                     f"(strongest: {_region_text(mism[0])}); score {sb:.2f}.")
    else:
        parts.append(f"Against {ref} the dynamic Allan deviation shows no region beyond the threshold, "
                     f"but matched tests do (score {sb:.2f}).")
    if res.accepted:
        parts.append("Missing physics, in order of importance: "
                     + "; ".join(_effect_summary(a.cand.kind, a.cand.params, _model_noise(res))
                                 for a in res.accepted) + ".")
        if sa <= 1.5 and not mism_after:
            parts.append(f"With these added the recording is within chance (score {sa:.2f}, no mismatch left): "
                         f"add them to the sensor model (--out-model) or remove the deterministic ones "
                         f"from the data (--out-corrected).")
        else:
            left = f"; strongest left: {_region_text(mism_after[0])}" if mism_after else ""
            parts.append(f"With these added the score is {sa:.2f} and {len(mism_after)} region(s) remain{left}: "
                         f"the catalogue does not explain everything - inspect those times and taus.")
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
    excess = [r for r in left if r["sign"] == "excess"]
    if not excess:
        return ""
    r = excess[0]
    fs = res.grid.fs_hz
    lines = spectral_lines(res.residual_after, fs, 0.371 / (2.0 * r["tau_max_s"]), min(fs / 2, 0.371 / (0.5 * r["tau_min_s"])))
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


def build_report(res: Result, recording_path: str, model_path: str | None) -> dict:
    mism = [r.as_json() for r in res.before.regions]
    mism_after = [r.as_json() for r in res.after.regions]
    effects = []
    for a in res.accepted:
        c = a.cand
        params = dict(c.params) if c.corrected_noise is not None else dict(c.effect().params)
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
            "sample_rate_hz": g.fs_hz, "n_samples": g.n, "window_s": g.window_s, "hop_s": g.hop_n / g.fs_hz,
            "n_windows": len(g.starts), "taus_s": g.tau_s.tolist(), "n_bootstrap": res.n_boot,
            "family_wise_alpha": res.before.null.alpha,
            "threshold_abs_z": round(res.before.null.threshold, 3),
            "threshold_abs_z_whole_record": round(res.before.null.threshold_whole, 3),
        },
    }
    if res.baseline:
        nz = res.model.noise
        rep["baseline_model"] = {"bias_dph": res.model.bias_dph, "Q_arcsec": nz.Q_arcsec, "N_dpsh": nz.N_dpsh,
                                 "B_dph": nz.B_dph, "K_dphsh": nz.K_dphsh, "R_dphh": nz.R_dphh}
    return _clean(rep)


def write_report(rep: dict, path: str) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(rep, fh, indent=2)
        fh.write("\n")


def console_summary(rep: dict) -> str:
    """A few lines for the terminal."""
    lines = [f"fogmon explain: {os.path.basename(rep['recording'])} vs {rep['model']}",
             f"  score before {rep['score_before']:.2f} -> after {rep['score_after']:.2f} (about 1 = chance)",
             f"  mismatch regions: {len(rep['mismatches'])} before, {len(rep['mismatches_after'])} after"]
    for r in rep["mismatches"][:5]:
        lines.append("    - " + _region_text(r))
    if rep["effects"]:
        lines.append("  effects added:")
        for e in rep["effects"]:
            lines.append(f"    + {_effect_summary(e['kind'], e['params'], e.get('model_noise'))} "
                         f"(score {e['score_before']:.2f} -> {e['score_after']:.2f})")
    else:
        lines.append("  effects added: none")
    for w in rep["warnings"]:
        lines.append(f"  warning {w['kind']}: {w['text']}")
    lines.append("  verdict: " + rep["verdict"])
    return "\n".join(lines)


def write_outputs(res: Result, out_model: str | None, out_corrected: str | None) -> None:
    """--out-model (fitted model TOML; a ``noise`` effect's corrections are in its [noise])
    and --out-corrected (recording minus the fitted deterministic effects and the Wiener
    estimate of any vibration_lines, replay log v1, same samples and aux columns)."""
    if out_model:
        save_model(res.fitted, out_model)
    if out_corrected:
        rec = res.recording
        idx = rec.grid_index()
        corrected = rec.rate_dph - res.deterministic_fit[idx]
        meta = dict(rec.meta)
        meta["sample_rate_hz"] = f"{rec.sample_rate_hz:g}"
        meta["corrected_by"] = "fogmon explain: " + (", ".join(
            a.cand.kind + (" (Wiener estimate of the line signal)" if a.cand.kind == "vibration_lines" else "")
            for a in res.accepted if a.cand.rate is not None) or "nothing")
        write_replay_log(out_corrected, rec.t_s, corrected, rec.aux, meta)


def _adev_band(a, null, fs):
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
        med, lo, hi, rec = _adev_band(a, a.null, g.fs_hz)
        ax[0, 0].fill_between(tau, lo, hi, color=col, alpha=0.15, label=f"model {label}: {100 * (1 - a.null.alpha):g} % family-wise band")
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


def write_rrd(res: Result, path: str) -> None:
    """The same evidence in a Rerun recording: z-maps as tensors, whole-record ADEV
    (log10) of the residual and bands against log10 tau, residual and fitted effects
    over time."""
    import rerun as rr

    rec = rr.RecordingStream("fogmon_explain")
    rec.save(path)
    g = res.grid
    for a, label in ((res.before, "before"), (res.after, "after")):
        rec.log(f"zmap_{label}", rr.Tensor(np.nan_to_num(a.z.T), dim_names=["tau_index", "window_index"]),
                static=True)
        med, lo, hi, r = _adev_band(a, a.null, g.fs_hz)
        ent = f"adev_{label}/log10_adev_dph"
        rec.log(ent, rr.SeriesLines(names=["recording residual", "model median", "band lo", "band hi"]), static=True)
        rec.send_columns(ent, indexes=[rr.TimeColumn("log10_tau_s_x1000", sequence=np.round(1000 * np.log10(g.tau_whole_s)).astype(np.int64))],
                         columns=rr.Scalars.columns(scalars=np.log10(np.column_stack([r, med, lo, hi]))))
    t = res.t_s
    k = max(1, len(t) // 20000)
    nb = len(t) // k
    y = np.where(res.valid, res.residual_before, np.nan)[: nb * k].reshape(nb, k)
    det = res.deterministic_fit[: nb * k].reshape(nb, k)
    rec.log("rate", rr.SeriesLines(names=["residual vs model (deg/h)", "fitted deterministic effects (deg/h)"]),
            static=True)
    rec.send_columns("rate", indexes=[rr.TimeColumn("time", duration=t[: nb * k: k])],
                     columns=rr.Scalars.columns(scalars=np.column_stack([np.nanmean(y, axis=1), det.mean(axis=1)])))
    rec.log("verdict", rr.TextDocument(verdict(res, [r.as_json() for r in res.before.regions],
                                               [r.as_json() for r in res.after.regions])), static=True)
    rec.flush()
