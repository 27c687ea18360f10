"""Sensor model file (docs/formats.md): a TOML description of a gyro that
``fogmon sim`` turns into a recording and ``fogmon explain`` compares recordings with.

``load_model`` validates strictly: an unknown table, key or effect kind, a missing
required parameter (every [noise] key is required: no silent 0), a negative value where
only >= 0 makes sense, a value outside its physical range, or a units-suffix typo
(``N_dph`` for ``N_dpsh``) is a one-line FogmonError naming the file and the key.
``save_model`` writes every parameter (defaults included) so that a saved model loads
back identically (``load_model(p) == model``).

``EFFECT_KINDS`` is the effect catalogue: for each kind its parameters (units, default,
constraint), the aux channel it needs and its nature:

- ``"mean"``: a deterministic rate contribution in deg/h (``fogmon.sim.effects.mean_rate_dph``),
  linear in its amplitude-type parameters;
- ``"white_level"``: adds to the white-noise level N in deg/sqrt(h) sample by sample
  (``fogmon.sim.effects.white_level_dpsh``); N = N0 + sum of these, the same white
  sequence scaled;
- ``"noise"``: an extra stochastic rate term (``markov``, ``lowpass_noise``, ...);
- ``"filter"``: acts on the whole simulated rate (``bandwidth``);
- ``"coefficients"``: corrected [noise] coefficients (``noise``): written by
  ``fogmon explain`` into its report only; a model file carries them in [noise].

``aux_response`` is mean-type with no fixed aux channel: its ``terms`` name the channels
they read (the feature grammar of ``fogmon.sim.features``).
"""
from __future__ import annotations

import difflib
import math
import os
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from itertools import pairwise

import numpy as np
import tomli_w

from fogmon.block import is_axis_name
from fogmon.errors import FogmonError
from fogmon.sim.features import term_text, validate_terms

#: IEEE-952 noise coefficient keys of the [noise] table and their units.
NOISE_UNITS = {
    "Q_arcsec": "arcsec (quantization noise)",
    "N_dpsh": "deg/sqrt(h) (angle random walk)",
    "B_dph": "deg/h (bias instability)",
    "K_dphsh": "deg/h/sqrt(h) (rate random walk)",
    "R_dphh": "deg/h^2 (rate ramp)",
}


@dataclass(frozen=True)
class Param:
    """One effect parameter: ``unit`` (text), ``type`` ("float", "int", "str", "list" of
    floats or "terms", the term tables of ``aux_response``), ``check`` ("any", ">=0",
    ">0"), ``default`` (None: required) and ``doc``."""

    unit: str
    doc: str
    type: str = "float"
    check: str = "any"
    default: object = None


@dataclass(frozen=True)
class EffectKind:
    """Catalogue entry: parameters by name, aux channel needed (or None), nature
    ("mean", "white_level", "noise", "filter"), a one-line description and ``summary``:
    fitted parameters -> one line with units (the explain report; None: the kind's name)."""

    params: dict
    aux: str | None
    nature: str
    description: str
    summary: Callable[[dict], str] | None = None

    def summarize(self, kind: str, p: dict) -> str:
        """One line naming this effect (``kind``) with parameters ``p`` and their units."""
        return self.summary(p) if self.summary is not None else kind

    @property
    def required(self) -> tuple[str, ...]:
        return tuple(k for k, p in self.params.items() if p.default is None)


#: default probabilities of an ``outliers`` effect's amplitude quantiles
OUTLIER_QUANTILE_PROBS = (0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 0.99, 1.0)

EFFECT_KINDS: dict[str, EffectKind] = {
    "thermal_drift": EffectKind(
        {
            "k0_poly_dph": Param("deg/h per degC^i", "K0(T) = sum_i c_i T^i, ascending powers of temp_c", "list"),
            "k1_pos": Param("deg/h per degC/s", "K1 while dT/dt * d2T/dt2 > 0 (heating accelerates)"),
            "k1_neg": Param("deg/h per degC/s", "K1 while dT/dt * d2T/dt2 <= 0 (heating decelerates)"),
            "k2_pos": Param("deg/h per degC/s^2", "K2 while dT/dt * d2T/dt2 > 0"),
            "k2_neg": Param("deg/h per degC/s^2", "K2 while dT/dt * d2T/dt2 <= 0"),
            "smooth_s": Param("s", "trailing moving-average length applied to temp_c first", check=">=0", default=10.0),
            "diff_step_s": Param("s", "step h of the 3-point backward differences", check=">0", default=1.0),
        },
        "temp_c", "mean",
        "K0(T) + K1*dT/dt + K2*d2T/dt2 on smoothed temperature, K1/K2 by acceleration branch",
        lambda p: (f"thermal drift (K1 {p['k1_pos']:.3g}/{p['k1_neg']:.3g} deg/h per degC/s, "
                   f"K0 slope {p['k0_poly_dph'][1] if len(p['k0_poly_dph']) > 1 else 0:.3g} deg/h/degC)")),
    "periodic": EffectKind(
        {
            "period_s": Param("s", "period of the sinusoid", check=">0"),
            "amplitude_dph": Param("deg/h", "amplitude", check=">=0"),
            "phase_rad": Param("rad", "phase at t = 0: A sin(2 pi t / P + phase)"),
        },
        None, "mean", "sinusoidal rate term (orbit, drill string, aliased vibration)",
        lambda p: f"periodic {p['amplitude_dph']:.3g} deg/h at period {p['period_s']:.5g} s"),
    "glitches": EffectKind(
        {
            "times_s": Param("s", "glitch times", "list"),
            "amplitudes_dph": Param("deg/h", "glitch amplitudes (same length as times_s)", "list"),
            "width_s": Param("s", "glitch duration; 0: the one sample nearest each time", check=">=0", default=0.0),
        },
        None, "mean", "isolated spikes added to the samples at the given times",
        lambda p: f"{len(p['times_s'])} glitch(es)"),
    "bias_step": EffectKind(
        {
            "t_s": Param("s", "time of the step"),
            "step_dph": Param("deg/h", "bias change for t >= t_s"),
        },
        None, "mean", "abrupt bias change (power interruption, shock)",
        lambda p: f"bias step {p['step_dph']:+.3g} deg/h at t = {p['t_s']:.6g} s"),
    "vibration_noise": EffectKind(
        {"n_gain_dpsh_per_g": Param("deg/sqrt(h) per g", "N = N0 + gain * vib_g", check=">=0")},
        "vib_g", "white_level", "white-noise level rising with vibration",
        lambda p: f"vibration-driven ARW {p['n_gain_dpsh_per_g']:.3g} deg/sqrt(h) per g"),
    "rate_ramp": EffectKind(
        {
            "slope_dphh": Param("deg/h^2", "rate += slope * (t - t0) / 3600 for t >= t0"),
            "t0_s": Param("s", "start of the ramp"),
        },
        None, "mean", "linear drift of the rate",
        lambda p: f"rate ramp {p['slope_dphh']:+.3g} deg/h^2 from t = {p['t0_s']:.6g} s"),
    "scale_factor": EffectKind(
        {
            "ppm": Param("ppm", "scale-factor error (mean of positive and negative)"),
            "asym_ppm": Param("ppm", "asymmetry: scale factor for rot_dps > 0 minus that for < 0"),
        },
        "rot_dps", "mean", "scale-factor error on the reference rotation: 3600 rot (ppm +- asym/2) 1e-6",
        lambda p: f"scale-factor error {p['ppm']:.3g} ppm (asymmetry {p['asym_ppm']:.3g} ppm)"),
    "markov": EffectKind(
        {
            "tau_c_s": Param("s", "correlation time", check=">0"),
            "sigma_dph": Param("deg/h", "standard deviation of the process", check=">=0"),
        },
        None, "noise", "first-order Gauss-Markov (exponentially correlated) rate noise",
        lambda p: f"Gauss-Markov noise {p['sigma_dph']:.3g} deg/h, correlation time {p['tau_c_s']:.4g} s"),
    "temperature_noise": EffectKind(
        {
            "n_gain_dpsh_per_c": Param("deg/sqrt(h) per degC", "N = N0 + gain * (temp_c - t_ref_c), floored at 0"),
            "t_ref_c": Param("degC", "reference temperature"),
        },
        "temp_c", "white_level", "white-noise level changing with temperature",
        lambda p: (f"temperature-driven ARW {p['n_gain_dpsh_per_c']:.3g} deg/sqrt(h) per degC "
                   f"(ref {p['t_ref_c']:.3g} degC)")),
    "warm_up": EffectKind(
        {
            "amplitude_dph": Param("deg/h", "rate += A exp(-(t - t0) / tau) for t >= t0"),
            "tau_s": Param("s", "settling time constant", check=">0"),
            "t0_s": Param("s", "power-on (or power-cycle) time"),
        },
        None, "mean", "exponential settling after power-on",
        lambda p: f"warm-up {p['amplitude_dph']:+.3g} deg/h settling with tau = {p['tau_s']:.4g} s"),
    "bandwidth": EffectKind(
        {
            "cutoff_hz": Param("Hz", "Butterworth -3 dB frequency (with order; 0 when taps are given)", check=">=0",
                               default=0.0),
            "order": Param("", "Butterworth order (with cutoff_hz)", "int", ">=0", default=0),
            "taps": Param("", "FIR coefficients instead of a Butterworth filter", "list", default=[]),
        },
        None, "filter", "the sensor's own low-pass/decimation filter applied to the whole rate",
        lambda p: f"sensor low-pass: Butterworth order {p['order']} at {p['cutoff_hz']:.4g} Hz"),
    "lowpass_noise": EffectKind(
        {
            "sigma_dph": Param("deg/h", "standard deviation of the filtered noise", check=">=0"),
            "cutoff_hz": Param("Hz", "Butterworth -3 dB frequency (below the Nyquist frequency)", check=">0"),
            "order": Param("", "Butterworth order", "int", ">0"),
        },
        None, "noise", "white noise through a Butterworth low-pass (the bandwidth kind's filter) added to the "
                       "rate: the filtered part of the sensor's white noise, beside an unfiltered white floor N",
        lambda p: (f"white noise through a Butterworth low-pass of order {p['order']} at {p['cutoff_hz']:.4g} Hz, "
                   f"{p['sigma_dph']:.4g} deg/h rms")),
    "outliers": EffectKind(
        {
            "rate_per_h": Param("1/h", "mean number of outliers per hour (a Poisson process on the sample grid)",
                                check=">=0"),
            "amplitude_quantiles_dph": Param("deg/h", "quantiles of |amplitude| at quantile_probs (simulated by "
                                             "interpolating them)", "list", ">=0"),
            "quantile_probs": Param("", "probabilities of amplitude_quantiles_dph, increasing from 0 to 1", "list",
                                    ">=0", default=list(OUTLIER_QUANTILE_PROBS)),
            "positive_fraction": Param("", "share of positive amplitudes", check=">=0", default=0.5),
            "count": Param("", "outliers found in the recording (informational)", "int", ">=0", default=0),
            "rate_per_sample": Param("", "count / valid samples (informational)", check=">=0", default=0.0),
            "contamination_fraction": Param("", "fitted share of contaminated samples in the contaminated-Gaussian "
                                            "mixture of the spike test (informational)", check=">=0", default=0.0),
            "contamination_sd_ratio": Param("", "standard deviation of the contaminated samples over the clean "
                                            "noise's, same mixture (informational)", check=">=0", default=0.0),
            "times_file": Param("", "CSV listing every outlier (time_s, amplitude_dph, abs_z), relative to the "
                                "file that names it (informational)", "str", default=""),
        },
        None, "noise", "heavy-tailed outlier population: spikes at a rate with an amplitude distribution",
        lambda p: (f"outlier population: {p['count']} outliers ({p['rate_per_h']:.4g} per hour, "
                   f"{p['rate_per_sample']:.3g} per sample), |amplitude| median "
                   f"{float(np.interp(0.5, p['quantile_probs'], p['amplitude_quantiles_dph'])):.3g} deg/h, largest "
                   f"{p['amplitude_quantiles_dph'][-1]:.3g} deg/h"
                   + (f", all listed in {p['times_file']}" if p.get("times_file") else ""))),
    "vibration_lines": EffectKind(
        {
            "freq_hz": Param("Hz", "centre frequency of each line (below the Nyquist frequency)", "list", ">0"),
            "sigma_dph": Param("deg/h", "rms of each line", "list", ">=0"),
            "bandwidth_hz": Param("Hz", "-3 dB bandwidth of each line (band-pass edges freq_hz -+ bandwidth_hz/2)",
                                  "list", ">0"),
        },
        None, "noise", "narrowband random vibration: white noise through a 4-pole band-pass per line",
        lambda p: "vibration lines " + ", ".join(f"{f:.4g} Hz ({s:.3g} deg/h rms, {w:.3g} Hz wide)" for f, s, w in
                                                  zip(p["freq_hz"], p["sigma_dph"], p["bandwidth_hz"], strict=True))),
    "aux_response": EffectKind(
        {
            "terms": Param("deg/h per unit of the feature", "terms {feature, coef, coef_lo, coef_hi, unit, physics, "
                           "colinear}: rate += sum of coef x feature (fogmon.sim.features: NAME, NAME^2, abs(NAME), "
                           "d(NAME)/dt, NAME*NAME2)", "terms"),
            "physics": Param("", "short physics name(s) of the law (fogmon explain's physics table)", "str",
                             default=""),
            "smooth_s": Param("s", "trailing moving-average length applied to a channel before d(NAME)/dt",
                              check=">=0", default=10.0),
            "diff_step_s": Param("s", "step h of the 3-point backward differences of d(NAME)/dt", check=">0",
                                 default=1.0),
            "offset_dph": Param("deg/h", "constant added to the law: fogmon explain sets it so the law averages to 0 "
                                "over the recording it was fitted on (the model's bias stays that record's mean)",
                                default=0.0),
        },
        None, "mean", "rate error following measured conditions: a sparse sum of coefficient x feature of the aux "
                      "channels or of another axis's rate",
        lambda p: "; ".join(term_text(t) for t in p["terms"])),
    "noise": EffectKind(
        {f"{k}{suffix}": Param(u.split(" (")[0], f"corrected {k}{' ' + what if what else ''}", check=">=0")
         for k, u in NOISE_UNITS.items() for suffix, what in (("", ""), ("_lo", "interval low end"),
                                                                ("_hi", "interval high end"))},
        None, "coefficients", "the model's own IEEE-952 coefficients corrected (report only; `out_model` "
                              "writes them into [noise])",
        lambda p: "corrected noise: " + ", ".join(f"{k} {p[k]:.4g} [{p[k + '_lo']:.4g}, {p[k + '_hi']:.4g}]"
                                                  for k in NOISE_UNITS if k in p)),
}


@dataclass
class Noise:
    """IEEE Std 952 noise coefficients: Q arcsec, N deg/sqrt(h), B deg/h,
    K deg/h/sqrt(h), R deg/h^2 (all >= 0)."""

    Q_arcsec: float = 0.0
    N_dpsh: float = 0.0
    B_dph: float = 0.0
    K_dphsh: float = 0.0
    R_dphh: float = 0.0


@dataclass
class Effect:
    """A physical effect: ``kind`` from EFFECT_KINDS and its parameters by name; ``axes``
    the axes it acts on (empty: every axis)."""

    kind: str
    params: dict = field(default_factory=dict)
    axes: tuple[str, ...] = ()


@dataclass
class SensorModel:
    """A simulated gyro: sample rate (Hz), constant bias (deg/h), IEEE-952 noise,
    effects, and free-form ``meta`` strings (the optional [meta] table). Several axes:
    ``axis_noise`` holds each axis's [noise.<axis>] coefficients (``noise`` is then the
    [noise] defaults they override); ``for_axis(name)`` is one axis's model."""

    sample_rate_hz: float
    bias_dph: float = 0.0
    noise: Noise = field(default_factory=Noise)
    effects: list[Effect] = field(default_factory=list)
    meta: dict[str, str] = field(default_factory=dict)
    axis_noise: dict[str, Noise] = field(default_factory=dict)

    @property
    def axes(self) -> tuple[str, ...]:
        """The axes the model names ([noise.<axis>] tables); () for a one-axis model or
        one whose noise is the same on every axis."""
        return tuple(self.axis_noise)

    def for_axis(self, name: str) -> SensorModel:
        """The one-axis model of axis ``name``: its noise, the effects that act on it.
        A model without axis tables gives the same noise on every axis."""
        if self.axis_noise and name not in self.axis_noise:
            raise FogmonError(f"the model has no [noise.{name}] table (its axes: {', '.join(self.axes)})")
        effects = [Effect(e.kind, e.params) for e in self.effects if not e.axes or name in e.axes]
        return SensorModel(self.sample_rate_hz, self.bias_dph, self.axis_noise.get(name, self.noise), effects,
                           dict(self.meta))


def _close(key: str, options) -> str:
    m = difflib.get_close_matches(key, list(options), n=1, cutoff=0.5)
    return f"; did you mean {m[0]!r}?" if m else ""


def _number(v, where: str, check: str = "any", integer: bool = False):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise FogmonError(f"{where}: expected a number, got {v!r}")
    if integer:
        if isinstance(v, float) and not v.is_integer():
            raise FogmonError(f"{where}: expected an integer, got {v!r}")
        v = int(v)
    else:
        v = float(v)
        if not math.isfinite(v):
            raise FogmonError(f"{where}: must be a finite number, got {v!r}")
    if check == ">=0" and v < 0:
        raise FogmonError(f"{where}: must be >= 0, got {v!r}")
    if check == ">0" and v <= 0:
        raise FogmonError(f"{where}: must be > 0, got {v!r}")
    return v


def validate_effect(kind: str, params: dict, where: str = "effect") -> Effect:
    """Check ``params`` against the catalogue and return a normalized Effect with every
    default filled in (floats as float, lists as list[float]). ``where`` prefixes errors."""
    if kind not in EFFECT_KINDS:
        raise FogmonError(f"{where}: unknown effect kind {kind!r} "
                          f"(known: {', '.join(EFFECT_KINDS)}){_close(str(kind), EFFECT_KINDS)}")
    spec = EFFECT_KINDS[kind]
    if spec.nature == "coefficients":
        raise FogmonError(f"{where}: kind {kind!r} is what fogmon explain reports when the model's own IEEE-952 "
                          f"coefficients are wrong; a model file carries corrected values in its [noise] table")
    where = f"{where} ({kind})"
    for k in params:
        if k not in spec.params:
            raise FogmonError(f"{where}: unknown parameter {k!r} (expected: {', '.join(spec.params)})"
                              f"{_close(k, spec.params)}")
    out = {}
    for k, p in spec.params.items():
        if k not in params:
            if p.default is None:
                raise FogmonError(f"{where}: missing parameter {k!r} ({p.unit}: {p.doc})")
            out[k] = list(p.default) if isinstance(p.default, list) else p.default
            continue
        v = params[k]
        if p.type == "terms":
            out[k] = validate_terms(v, where)
        elif p.type == "str":
            if not isinstance(v, str):
                raise FogmonError(f"{where}: parameter {k!r} must be a string, got {v!r}")
            out[k] = v
        elif p.type == "list":
            if not isinstance(v, (list, tuple)):
                raise FogmonError(f"{where}: parameter {k!r} must be a list of numbers, got {v!r}")
            out[k] = [_number(x, f"{where}: {k}[{i}]", p.check) for i, x in enumerate(v)]
        else:
            out[k] = _number(v, f"{where}: parameter {k!r}", p.check, integer=p.type == "int")
    _check_effect(kind, out, where)
    return Effect(kind, out)


def _check_effect(kind: str, p: dict, where: str) -> None:
    """Cross-parameter rules."""
    if kind == "glitches" and len(p["times_s"]) != len(p["amplitudes_dph"]):
        raise FogmonError(f"{where}: times_s and amplitudes_dph must have the same length "
                          f"({len(p['times_s'])} vs {len(p['amplitudes_dph'])})")
    if kind == "outliers":
        _check_outliers(p, where)
    if kind == "scale_factor":
        worst = abs(p["ppm"]) + abs(p["asym_ppm"]) / 2
        if worst >= 1e6:
            raise FogmonError(f"{where}: |ppm| + |asym_ppm|/2 = {worst:g} ppm; a scale-factor error of 100 % "
                              f"(1e6 ppm) or more makes the gyro read zero or the wrong sign: a wrong unit?")
    if kind == "vibration_lines" and not len(p["freq_hz"]) == len(p["sigma_dph"]) == len(p["bandwidth_hz"]):
        raise FogmonError(f"{where}: freq_hz, sigma_dph and bandwidth_hz must have one entry per line "
                          f"({len(p['freq_hz'])}, {len(p['sigma_dph'])}, {len(p['bandwidth_hz'])})")
    if kind == "bandwidth":
        butter = p["cutoff_hz"] > 0 or p["order"] > 0
        if butter == bool(p["taps"]):
            raise FogmonError(f"{where}: give either cutoff_hz and order (Butterworth) or taps (FIR), not "
                              f"{'both' if butter else 'neither'}")
        if butter and not (p["cutoff_hz"] > 0 and p["order"] >= 1):
            raise FogmonError(f"{where}: a Butterworth filter needs cutoff_hz > 0 and order >= 1")


def _check_outliers(p: dict, where: str) -> None:
    probs, q = p["quantile_probs"], p["amplitude_quantiles_dph"]
    if len(probs) != len(q) or len(q) < 2:
        raise FogmonError(f"{where}: quantile_probs and amplitude_quantiles_dph need the same length, at least 2 "
                          f"({len(probs)} vs {len(q)})")
    if probs[0] != 0.0 or probs[-1] != 1.0 or any(b <= a for a, b in pairwise(probs)):
        raise FogmonError(f"{where}: quantile_probs must increase strictly from 0 to 1, got {probs}")
    if any(b < a for a, b in pairwise(q)):
        raise FogmonError(f"{where}: amplitude_quantiles_dph must not decrease, got {q}")
    if p["positive_fraction"] > 1.0:
        raise FogmonError(f"{where}: positive_fraction must be <= 1, got {p['positive_fraction']:g}")


def validate_model(model: SensorModel, where: str = "model") -> SensorModel:
    """Validate a SensorModel built in code (same rules as load_model); returns a
    normalized copy."""
    sample_rate_hz = _number(model.sample_rate_hz, f"{where}: [sensor] sample_rate_hz", ">0")
    bias = _number(model.bias_dph, f"{where}: [sensor] bias_dph")
    noise = Noise(**{f.name: _number(getattr(model.noise, f.name), f"{where}: [noise] {f.name}", ">=0")
                     for f in fields(Noise)})
    axis_noise = {}
    for a, nz in model.axis_noise.items():
        _check_axis_name(a, f"{where}: [noise.{a}]")
        axis_noise[a] = Noise(**{f.name: _number(getattr(nz, f.name), f"{where}: [noise.{a}] {f.name}", ">=0")
                                 for f in fields(Noise)})
    effects = []
    for i, e in enumerate(model.effects):
        at = f"{where}: [[effect]] #{i + 1}"
        for a in e.axes:
            _check_axis_name(a, f"{at}: axes")
            if axis_noise and a not in axis_noise:
                raise FogmonError(f"{at}: axes names {a!r}, which has no [noise.{a}] table "
                                  f"(axes: {', '.join(axis_noise)})")
        effects.append(replace(validate_effect(e.kind, e.params, at), axes=tuple(e.axes)))
    for i, e in enumerate(effects):
        if e.kind in ("bandwidth", "lowpass_noise") and e.params["cutoff_hz"] >= sample_rate_hz / 2:
            raise FogmonError(f"{where}: [[effect]] #{i + 1} ({e.kind}): cutoff_hz must be below the "
                              f"Nyquist frequency {sample_rate_hz / 2:g} Hz, got {e.params['cutoff_hz']:g}")
        if e.kind == "vibration_lines":
            for j, (f, bw) in enumerate(zip(e.params["freq_hz"], e.params["bandwidth_hz"], strict=True)):
                if not (f + bw / 2 < sample_rate_hz / 2 and bw < 2 * f):
                    raise FogmonError(f"{where}: [[effect]] #{i + 1} (vibration_lines): line {j + 1} at "
                                      f"{f:g} Hz with bandwidth {bw:g} Hz must lie between 0 and the Nyquist "
                                      f"frequency {sample_rate_hz / 2:g} Hz (freq_hz +- bandwidth_hz/2)")
    return SensorModel(sample_rate_hz, bias, noise, effects, {str(k): str(v) for k, v in model.meta.items()},
                       axis_noise)


def _check_axis_name(name: object, where: str) -> None:
    """An axis name is letters and digits (it becomes part of column names)."""
    if not is_axis_name(name):
        raise FogmonError(f"{where}: an axis name is letters and digits, got {name!r}")


def _table(doc: dict, name: str, where: str) -> dict:
    t = doc.get(name, {})
    if not isinstance(t, dict):
        raise FogmonError(f"{where}: [{name}] must be a table")
    return t


def model_from_dict(doc: dict, where: str = "model") -> SensorModel:
    """A validated SensorModel from the parsed TOML document."""
    top = {"sensor", "noise", "effect", "meta"}
    for k in doc:
        if k not in top:
            raise FogmonError(f"{where}: unknown table or key {k!r} (expected: [sensor], [noise], "
                              f"[[effect]], [meta]){_close(k, top)}")
    sensor = _sensor_table(doc, where)
    noise = _noise_table(doc, where)
    effects = doc.get("effect", [])
    if not isinstance(effects, list):
        raise FogmonError(f"{where}: 'effect' must be an array of tables: write [[effect]]")
    elist = []
    for i, e in enumerate(effects):
        if not isinstance(e, dict) or "kind" not in e:
            raise FogmonError(f"{where}: [[effect]] #{i + 1}: missing key 'kind'")
        params = {k: v for k, v in e.items() if k not in ("kind", "axes")}
        axes = e.get("axes", [])
        if not isinstance(axes, list) or not axes and "axes" in e:
            raise FogmonError(f"{where}: [[effect]] #{i + 1}: axes must be a non-empty list of axis names, "
                              f"got {axes!r}")
        elist.append(Effect(e["kind"], params, tuple(axes)))
    meta = _table(doc, "meta", where)
    shared, per_axis = noise
    model = SensorModel(sensor["sample_rate_hz"], sensor.get("bias_dph", 0.0), Noise(**shared), elist, meta,
                        {a: Noise(**t) for a, t in per_axis.items()})
    return validate_model(model, where)


def _sensor_table(doc: dict, where: str) -> dict:
    """The [sensor] table: sample_rate_hz (required), bias_dph, nothing else."""
    sensor = _table(doc, "sensor", where)
    for k in sensor:
        if k not in ("sample_rate_hz", "bias_dph"):
            raise FogmonError(f"{where}: [sensor] unknown key {k!r} (expected: sample_rate_hz, bias_dph)"
                              f"{_close(k, ('sample_rate_hz', 'bias_dph'))}")
    if "sample_rate_hz" not in sensor:
        raise FogmonError(f"{where}: [sensor] missing key 'sample_rate_hz' (Hz)")
    return sensor


def _noise_table(doc: dict, where: str) -> tuple[dict, dict[str, dict]]:
    """The [noise] table: every IEEE-952 term (NOISE_UNITS), nothing else; or
    [noise.<axis>] tables, each term of which overrides a [noise] one (every term must
    then be given one way or the other). Returns (the shared terms, each axis's terms)."""
    if "noise" not in doc:
        raise FogmonError(f"{where}: no [noise] table: give {', '.join(NOISE_UNITS)} "
                          f"(IEEE-952 terms; 0.0 for a term the gyro does not have)")
    noise = _table(doc, "noise", where)
    shared = {k: v for k, v in noise.items() if not isinstance(v, dict)}
    tables = {k: v for k, v in noise.items() if isinstance(v, dict)}
    for k in shared:
        if k not in NOISE_UNITS:
            raise FogmonError(f"{where}: [noise] unknown key {k!r} (expected: "
                              f"{', '.join(f'{n} [{u}]' for n, u in NOISE_UNITS.items())}, or [noise.<axis>] "
                              f"tables){_close(k, NOISE_UNITS)}")
    per_axis = {}
    for a, t in tables.items():
        _check_axis_name(a, f"{where}: [noise.{a}]")
        for k in t:
            if k not in NOISE_UNITS:
                raise FogmonError(f"{where}: [noise.{a}] unknown key {k!r} (expected: "
                                  f"{', '.join(NOISE_UNITS)}){_close(k, NOISE_UNITS)}")
        per_axis[a] = {**shared, **t}
    for name, terms in ([("noise", shared)] if not tables else [(f"noise.{a}", t) for a, t in per_axis.items()]):
        missing = [k for k in NOISE_UNITS if k not in terms]
        if missing:
            raise FogmonError(f"{where}: [{name}] missing {', '.join(f'{k} [{NOISE_UNITS[k]}]' for k in missing)}: "
                              f"every IEEE-952 term is required (0.0 for a term the gyro does not have)")
    return {k: shared.get(k, 0.0) for k in NOISE_UNITS}, per_axis


def model_to_dict(model: SensorModel) -> dict:
    """The TOML document of a model (every parameter written)."""
    model = validate_model(model)
    doc: dict = {}
    if model.meta:
        doc["meta"] = dict(model.meta)
    doc["sensor"] = {"sample_rate_hz": model.sample_rate_hz, "bias_dph": model.bias_dph}
    doc["noise"] = {f.name: getattr(model.noise, f.name) for f in fields(Noise)}
    for a, nz in model.axis_noise.items():
        doc["noise"][a] = {f.name: getattr(nz, f.name) for f in fields(Noise)}
    if model.effects:
        doc["effect"] = [{"kind": e.kind, **({"axes": list(e.axes)} if e.axes else {}), **e.params}
                         for e in model.effects]
    return doc


def load_model(path: str | os.PathLike) -> SensorModel:
    """Read and validate a sensor model TOML file (docs/formats.md)."""
    path = os.fspath(path)
    name = os.path.basename(path)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except FileNotFoundError:
        raise FogmonError(f"{path}: no such model file") from None
    except IsADirectoryError:
        raise FogmonError(f"{path}: is a directory, not a model file") from None
    except tomllib.TOMLDecodeError as e:
        raise FogmonError(f"{name}: not valid TOML: {e}") from None
    except UnicodeDecodeError:
        raise FogmonError(f"{name}: not valid TOML: not UTF-8 text") from None
    except OSError as e:
        raise FogmonError(f"{path}: cannot read: {e.strerror}") from None
    return model_from_dict(doc, name)


def dumps_model(model: SensorModel) -> str:
    """The TOML text of a model, with a header comment naming the units."""
    head = ("# fogmon sensor model (docs/formats.md). Units: rate deg/h, time s; noise: "
            + ", ".join(f"{k} {u.split(' (')[0]}" for k, u in NOISE_UNITS.items()) + "\n")
    return head + tomli_w.dumps(model_to_dict(model))


def save_model(model: SensorModel, path: str | os.PathLike) -> None:
    """Write a model file that ``load_model`` reads back identically."""
    text = dumps_model(model)
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
