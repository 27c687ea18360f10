"""Development cases of `fogmon explain` on a real gyro's noise (issue 29, item 6): every
effect kind, catalogue and ``aux_response``, added to public real recordings (rebuilt
by validation/real_recordings.py) and explained against the model fitted on the
untouched record (its `--out-model`: the baseline and the effects explain finds there).
The background is then quantized, non-Gaussian and wanders by itself, as a real sensor
does, instead of the simulator's noise.

A case passes when exactly the added kind is accepted (nothing else invented: a kind
that explain also names on the untouched record against that model is the background's
own and does not count), its parameters are recovered (the tolerances of
validation/explain_devset.py; a law's terms as in validation/devset_aux.py), the
correction's gain (rms of the added deterministic effect over the rms of what the
fitted correction of the added kind leaves of it) is at least 3, and the score
ends at most 1.5 or at most the untouched record's own score against its model. Nulls:
the untouched record with aux channels that act on nothing must get nothing.

Run by validation/explain_devset.py (rows ``real_*``); the untouched models are fitted
once per version of fogmon's sources and kept in $FOGMON_DEVSET_CACHE (default: the
system's temporary folder).
"""
from __future__ import annotations

import hashlib
import math
import os
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from devset_aux import channels, law_checks
from real_recordings import DEFAULT_DATA, data_path, load_manifest

import fogmon
from fogmon.explain.explainer import explain, explain_without_model, without_motion
from fogmon.explain.options import Options
from fogmon.formats.recording import Recording
from fogmon.formats.replay_log import read_replay_log
from fogmon.sim import effects as fx
from fogmon.sim.model import (
    EFFECT_KINDS,
    OUTLIER_QUANTILE_PROBS,
    Effect,
    Noise,
    SensorModel,
    load_model,
    save_model,
    validate_effect,
)
from fogmon.sim.simulate import simulate


def _code_digest() -> str:
    """A digest of fogmon's Python sources: the untouched models depend on explain's code,
    so a cache made by other code is not read (a stale one judged the cases against the
    previous baseline)."""
    h = hashlib.sha256()
    root = Path(fogmon.__file__).parent
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:12]


CACHE = Path(os.environ.get("FOGMON_DEVSET_CACHE", tempfile.gettempdir())) / f"fogmon_devset_real-{_code_digest()}"
#: backgrounds: manifest name -> seconds used from the start (None: all)
BACKGROUNDS = {"adis16405_x": 7200.0, "px4_quiet_z": None, "psins_rlg_z": None}


@dataclass
class RealCase:
    """An effect (``effect``; or an ``aux_response`` law ``terms`` along the aux channels
    of run ``run``, devset_aux.channels) added to ``background``; ``model_n_factor``: the
    model's N scaled by it (the ``noise`` kind: the record is untouched, the model
    wrong); ``expect``: the kinds explain must accept."""

    name: str
    background: str
    expect: tuple[str, ...]
    effect: Effect | None = None
    run: str | None = None
    terms: dict[str, float] = field(default_factory=dict)
    physics: dict[str, str] = field(default_factory=dict)
    model_n_factor: float = 1.0


def available(data_dir: str = DEFAULT_DATA) -> list[str]:
    """The backgrounds whose recordings are there."""
    entries = {e["name"]: e for e in load_manifest()}
    return [b for b in BACKGROUNDS if data_path(entries[b], data_dir).exists()]


def background(name: str, data_dir: str = DEFAULT_DATA) -> Recording:
    """The real record ``name`` (its first BACKGROUNDS[name] s), platform motion left out
    as explain does."""
    entry = next(e for e in load_manifest() if e["name"] == name)
    rec = read_replay_log(data_path(entry, data_dir))
    span = BACKGROUNDS[name]
    if span is not None:
        keep = rec.t_s < rec.t_s[0] + span
        rec = Recording(rec.t_s[keep], rec.rate_dph[keep], {k: v[keep] for k, v in rec.aux.items()},
                        dict(rec.meta), rec.path)
    rec.path = f"{name}.csv"
    return without_motion(rec)[0]


def untouched_model(name: str, rec: Recording) -> tuple[SensorModel, float, frozenset[str]]:
    """The model explain fits on the untouched record (baseline + effects found), the
    record's score against it and the kinds explain still names there (the background's
    own: a real record is not exactly its fitted model), cached in CACHE."""
    path = CACHE / f"{name}.toml"
    if not path.exists():
        CACHE.mkdir(parents=True, exist_ok=True)
        res = explain_without_model(rec, Options(seed=7))
        save_model(replace(res.fitted, meta={"untouched_effects": ",".join(a.cand.kind for a in res.accepted)}),
                   path)
    model = load_model(path)
    score_path = CACHE / f"{name}.score"
    if not score_path.exists():
        res = explain(rec, model, Options(seed=8))
        score_path.write_text(f"{res.after.score.value!r}\n{','.join(a.cand.kind for a in res.accepted)}\n")
    score, kinds = (score_path.read_text().split("\n") + [""])[:2]
    return model, float(score), frozenset(k for k in kinds.split(",") if k)


def noise_std(rec: Recording) -> float:
    """Per-sample white-noise std (deg/h) of a real record: the std of first differences / sqrt(2)."""
    return float(np.std(np.diff(rec.rate_dph)) / math.sqrt(2.0))


def cases() -> list[RealCase]:
    """The real-background cases; amplitudes are set per record from its noise (``added``)."""
    out = [RealCase("real_null_adis16405_x_wander", "adis16405_x", (), run="wander"),
           RealCase("real_null_px4_quiet_z_wander", "px4_quiet_z", (), run="wander")]
    for bg in ("adis16405_x",):
        out += [
            RealCase(f"real_aux_shupe_{bg}", bg, ("aux_response",), run="chamber",
                     terms={"d(temp_coil_c)/dt": 25.0}, physics={"d(temp_coil_c)/dt": "thermal transient (Shupe)"}),
            RealCase(f"real_aux_rectification_{bg}", bg, ("aux_response",), run="vibration",
                     terms={"vib_g^2": 0.03}, physics={"vib_g^2": "vibration rectification"}),
            RealCase(f"real_aux_faraday_{bg}", bg, ("aux_response",), run="coil", terms={"mag_ut": 0.004},
                     physics={"mag_ut": "magnetic (Faraday) sensitivity"}),
            RealCase(f"real_aux_g_sensitivity_sway_{bg}", bg, ("aux_response",), run="sway", terms={"acc_g": 0.5},
                     physics={"acc_g": "g-sensitivity"}),
            RealCase(f"real_aux_supply_{bg}", bg, ("aux_response",), run="supply", terms={"supply_v": 0.3},
                     physics={"supply_v": "supply sensitivity"}),
        ]
        out += [RealCase(f"real_{k}_{bg}", bg, (k,), Effect(k, {})) for k in CATALOGUE]
        out.append(RealCase(f"real_noise_{bg}", bg, ("noise",), model_n_factor=0.75))
    # px4_quiet_z is 59 s long, two correlation times of the vibration level: at 0.1 s per g^2 the
    # coefficient's standard error was 23 % of it (13.0 [7.2, 18.9], truth 9.8), the 25 % tolerance one
    # standard error; at 0.2 the law still changes the raw std by under 3 %
    out += [RealCase("real_aux_rectification_px4_quiet_z", "px4_quiet_z", ("aux_response",), run="vibration",
                     terms={"vib_g^2": 0.2}, physics={"vib_g^2": "vibration rectification"}),
            RealCase("real_aux_faraday_psins_rlg_z", "psins_rlg_z", ("aux_response",), run="coil",
                     terms={"mag_ut": 0.004}, physics={"mag_ut": "magnetic (Faraday) sensitivity"}),
            RealCase("real_bias_step_psins_rlg_z", "psins_rlg_z", ("bias_step",), Effect("bias_step", {}))]
    return out


#: the rate table's largest |rot_dps| (deg/s) of the scale_factor case
ROT_PEAK_DPS = 30.0
#: the catalogue kinds added to a real background (``noise``: a wrong model instead)
CATALOGUE = ("thermal_drift", "periodic", "bias_step", "rate_ramp", "warm_up", "glitches", "scale_factor",
             "markov", "vibration_noise", "temperature_noise", "bandwidth", "outliers", "vibration_lines")


def concrete(case: RealCase, rec: Recording, s: float) -> tuple[Effect | None, dict[str, float]]:
    """The effect with amplitudes for a record of per-sample noise std ``s`` (deg/h) and
    duration T: concealed like the development set's cases where the kind allows."""
    T, fs = rec.duration_s, rec.sample_rate_hz
    k = case.effect.kind if case.effect else None
    terms = {f: c * s for f, c in case.terms.items()}
    p = {
        # 3x the simulated case's: at 1x (drift 174 deg/h p-p on adis16405_x, 7x its B) the sensor's own
        # bias wander hides it (judged gain 25.7 against a bar of 40; 98.8 against the model's B alone)
        "thermal_drift": {"k0_poly_dph": [0.0, 0.006 * s], "k1_pos": 48.0 * s, "k1_neg": 24.0 * s, "k2_pos": 0.0,
                          "k2_neg": 0.0, "smooth_s": 30.0, "diff_step_s": 10.0},
        "periodic": {"period_s": T / 12.3, "amplitude_dph": 0.2 * s, "phase_rad": 1.0},
        "bias_step": {"t_s": float(rec.t_s[0]) + 0.41 * T, "step_dph": 0.25 * s},
        "rate_ramp": {"slope_dphh": 0.25 * s * 3600.0 / T * 2, "t0_s": float(rec.t_s[0]) + 0.25 * T},
        "warm_up": {"amplitude_dph": 0.45 * s, "tau_s": T / 12.0, "t0_s": float(rec.t_s[0])},
        # 8-9 s: a real MEMS record's noise is white at the sample scale, where a one-sample spike of
        # 3 s has z ~ 3 (measured 1.8-4.3 on adis16405_x) below the Bonferroni bar over 720000 samples
        # (~5.5): no test can find it (docs/explain.md, tolerances); the question is real tails
        "glitches": {"times_s": [float(rec.t_s[0]) + f * T for f in (0.11, 0.37, 0.52, 0.78, 0.93)],
                     "amplitudes_dph": [8.0 * s, -8.0 * s, 9.0 * s, -9.0 * s, 8.0 * s]},
        # peak 0.4 s over the table's 30 deg/s, asymmetry half the symmetric term (the simulated case's
        # 20 + 10 ppm is 0.4 s of its FOG; on adis16405_x it was 0.003 s, chi2 ~ 2: not findable)
        "scale_factor": {"ppm": 0.4 * s / (1.5 * 3600e-6 * ROT_PEAK_DPS),
                         "asym_ppm": 0.2 * s / (1.5 * 3600e-6 * ROT_PEAK_DPS)},
        "markov": {"tau_c_s": T / 240.0, "sigma_dph": 0.3 * s},
        "vibration_noise": {"n_gain_dpsh_per_g": 0.1},
        "temperature_noise": {"n_gain_dpsh_per_c": 0.004, "t_ref_c": 15.0},
        "bandwidth": {"cutoff_hz": 0.47 * fs, "order": 2},
        "outliers": {"rate_per_h": 0.0016 * fs * 3600.0,
                     "amplitude_quantiles_dph": [4.0 * s * ((1.0 - q) ** (-1 / 3) if q < 1 else 10.0)
                                                 for q in OUTLIER_QUANTILE_PROBS]},
        "vibration_lines": {"freq_hz": [0.03 * fs, 0.11 * fs], "sigma_dph": [0.2 * s, 0.15 * s],
                            "bandwidth_hz": [0.0005 * fs, 0.002 * fs]},
    }.get(k)
    return (validate_effect(k, p) if k else None), terms


def aux_for(case: RealCase, rec: Recording, seed: int) -> dict[str, np.ndarray]:
    """The aux channels the case's record carries."""
    t = rec.t_s
    aux = dict(channels(case.run, t, seed)) if case.run else {}
    k = case.effect.kind if case.effect else None
    if k in ("thermal_drift", "temperature_noise"):
        aux.update(channels("chamber", t, seed))
        aux["temp_c"] = aux.pop("temp_coil_c")
    if k == "vibration_noise":
        aux.update(channels("vibration", t, seed))
    if k == "scale_factor":
        aux["rot_dps"] = (ROT_PEAK_DPS * (2.0 * np.sin(2 * np.pi * t / 120.0) + np.sign(np.sin(2 * np.pi * t / 900.0)))
                          / 3.0)
    return aux


def build(case: RealCase, seed: int, data_dir: str = DEFAULT_DATA):
    """(modified record, model it is explained against, the untouched score and the kinds
    explain names on the untouched record (``untouched_model``), the added effect or law,
    the added deterministic rate (deg/h) on its samples, raw-std change)."""
    from fogmon.sim.noise import WhiteRate

    rec = background(case.background, data_dir)
    model, score0, own = untouched_model(case.background, rec)
    s = noise_std(rec)
    eff, terms = concrete(case, rec, s)
    aux = aux_for(case, rec, seed)
    fs, t = rec.sample_rate_hz, rec.t_s
    like = Recording(t, np.zeros(len(t)), aux, {"sample_rate_hz": repr(fs)}, rec.path)
    rate = rec.rate_dph.copy()
    det = np.zeros(len(t))
    if terms:
        law = validate_effect("aux_response", {"terms": [{"feature": f, "coef": c} for f, c in terms.items()]})
        det += fx.mean_rate_dph(law, t, aux, fs)
        eff = law
    elif eff is not None:
        nature = EFFECT_KINDS[eff.kind].nature
        if nature == "mean":
            det += fx.mean_rate_dph(eff, t, aux, fs)
            if eff.kind == "scale_factor":
                rate += 3600.0 * aux["rot_dps"]
        elif nature == "noise":
            rate += simulate(SensorModel(fs, 0.0, Noise(), [eff]), like=like, seed=seed).rate_dph
        elif nature == "white_level":  # the level becomes N0 + gain x channel: extra white noise in quadrature
            n0 = model.noise.N_dpsh
            lvl = n0 + fx.white_level_dpsh(eff, t, aux)
            extra = np.sqrt(np.maximum(lvl ** 2 - n0 ** 2, 0.0))
            # a stream of its own: channels() draws the aux channels from default_rng(seed), and the same
            # normals would make the noise's slow part a copy of vib_g's (a mean law the case never added)
            rate += WhiteRate(fs, np.random.default_rng(seed + 1)).generate(len(t), extra)
        elif nature == "filter":
            rate = fx.BandwidthFilter(eff.params, fs).apply(rate)
    change = float(np.std(rate + det - (3600.0 * aux["rot_dps"] if "rot_dps" in aux else 0.0))
                   / np.std(rec.rate_dph) - 1.0)
    out = Recording(t, rate + det, aux, dict(rec.meta), f"{case.name}.csv")
    if case.model_n_factor != 1.0:
        model = replace(model, noise=replace(model.noise, N_dpsh=model.noise.N_dpsh * case.model_n_factor))
    return out, model, (score0, own), eff, det, change


def correction_gain(res, det: np.ndarray, kinds) -> float:
    """rms of the added deterministic rate over the rms of what the fitted correction of
    the effects of ``kinds`` leaves of it (both centred over the valid samples); inf when
    nothing is left."""
    v = res.valid
    full = np.zeros(len(res.t_s))
    full[res.recording.grid_index()] = det
    u = full[v] - full[v].mean()
    mine = sum((a.cand.rate for a in res.accepted if a.cand.kind in kinds and a.cand.rate is not None),
               np.zeros(len(res.t_s)))
    fit = mine[v] - mine[v].mean()
    left = float(np.sqrt(np.mean((u - fit) ** 2)))
    return float(np.sqrt(np.mean(u ** 2))) / left if left > 0 else math.inf


def run_case(case: RealCase, seed: int, param_errors, invariants, verbose: bool = False) -> dict:
    """One row: found, named, recovery, correction gain, scores, PASS/FAIL."""
    rec, model, (score0, own), eff, det, change = build(case, seed)
    t0 = time.perf_counter()
    res = explain(rec, model, Options(seed=seed + 100))
    dt = time.perf_counter() - t0
    found = sorted({a.cand.kind for a in res.accepted})
    # what explain names on the untouched record against its own model is the background's
    # own (a real record is not exactly its fitted model), not invented by the added effect
    named = sorted(set(found) - (own - set(case.expect))) == sorted(case.expect)
    texts, ok = [], True
    if case.terms:
        texts, ok = law_checks(res, {f: c * noise_std(background(case.background)) for f, c in case.terms.items()},
                               case.physics)
    elif eff is not None or case.model_n_factor != 1.0:
        from types import SimpleNamespace

        fake = SimpleNamespace(effects=[eff] if eff is not None else [], sample_rate_hz=rec.sample_rate_hz,
                               model_noise=(replace(model.noise) if case.model_n_factor != 1.0 else None),
                               noise=replace(model.noise, N_dpsh=model.noise.N_dpsh / case.model_n_factor))
        texts, ok = param_errors(fake, res, rec)
    gain = correction_gain(res, det, set(case.expect)) if np.any(det) else None
    if gain is not None:
        texts.append(f"correction gain {gain:.3g}")
        ok &= gain >= 3.0
    problems = invariants(res, rec)
    sb, sa = res.before.score.value, res.after.score.value
    good = named and ok and not problems and sa <= max(1.5, 1.05 * score0)
    if verbose:
        for a in res.accepted:
            print(f"   + {a.cand.kind}: {a.cand.evidence}")
        for k, g, why in res.rejected[:6]:
            print(f"   - {k} {g:.1f}: {why}")
    return {"case": case.name, "n": len(rec), "conceal": "-", "raw_std": f"{100 * change:+.1f}%",
            "found": ",".join(found) or "-", "named": "yes" if named else "NO",
            "params": "; ".join(texts + problems + [f"untouched score {score0:.2f}"]),
            "score_before": sb, "score_after": sa,
            "regions": f"{len(res.before.regions)}->{len(res.after.regions)}", "time_s": dt, "pass": good}
