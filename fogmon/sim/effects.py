"""Physical effects (docs/formats.md) as pure functions of time, aux channels and
parameters. Natures (see ``fogmon.sim.model.EFFECT_KINDS``):

- mean-type: ``mean_rate_dph(effect, t_s, aux, sample_rate_hz)`` -> deterministic deg/h
  contribution (thermal_drift, periodic, glitches, bias_step, rate_ramp, scale_factor,
  warm_up, aux_response). Each is linear in its amplitude-type parameters, so a fitter can evaluate
  it with one coefficient set to 1 to get a regressor.
- white-level: ``white_level_dpsh(effect, t_s, aux)`` -> added ARW level in deg/sqrt(h)
  per sample (vibration_noise, temperature_noise); the simulator scales one white
  sequence by N0 + sum of these (floored at 0).
- noise: ``noise_generator(effect, sample_rate_hz, rng)`` -> a stateful generator (markov,
  lowpass_noise, outliers, vibration_lines).
- filter: ``BandwidthFilter(params, sample_rate_hz)`` applied to the whole simulated rate.

``lookback_s(effect)`` is how much earlier data a mean-type effect needs to be exact
at the first sample of a chunk (the streaming simulator prepends that much).
Time ``t_s`` is recording time in s (the recording's own clock when simulated ``like`` one).
"""
from __future__ import annotations

import numpy as np
from scipy.signal import lfilter, lfilter_zi, sosfilt, sosfilt_zi

from fogmon.errors import FogmonError
from fogmon.sim.features import Feature, parse_feature
from fogmon.sim.model import EFFECT_KINDS, Effect
from fogmon.sim.noise import GaussMarkov, LowpassNoise, NarrowbandLine, lowpass_filter


def _aux(effect: Effect, aux: dict) -> np.ndarray:
    name = EFFECT_KINDS[effect.kind].aux
    if name not in aux:
        raise FogmonError(f"effect {effect.kind!r} needs the aux channel {name!r}, which the input lacks "
                          f"(have: {', '.join(aux) or 'none'}); use `like` a recording with that column "
                          f"or a `scenario`")
    return np.asarray(aux[name], dtype=float)


def _fs(t_s: np.ndarray, sample_rate_hz: float | None) -> float:
    if sample_rate_hz:
        return float(sample_rate_hz)
    if len(t_s) < 2:
        raise ValueError("sample_rate_hz is needed for fewer than two samples")
    return 1.0 / float(np.median(np.diff(t_s)))


def smoothed_temperature(t_s, temp_c, smooth_s: float) -> np.ndarray:
    """Trailing moving average of temp_c (deg C) over the samples in (t - smooth_s, t];
    shorter at the start of the array. smooth_s = 0 returns temp_c."""
    t = np.asarray(t_s, dtype=float)
    x = np.asarray(temp_c, dtype=float)
    if smooth_s <= 0 or len(x) == 0:
        return x.copy()
    c = np.concatenate(([0.0], np.cumsum(x - x[0])))
    hi = np.arange(1, len(x) + 1)
    lo = np.searchsorted(t, t - smooth_s, side="right")
    return x[0] + (c[hi] - c[lo]) / (hi - lo)


#: Temperature changes below this fraction of |T| (deg C) per difference step are rounding,
#: not physics: dT/dt and d2T/dt2 that small are taken as 0, so the K1/K2 branch
#: (dT/dt * d2T/dt2 > 0) does not flip on rounding noise along a steady ramp or plateau.
#: Thermometers resolve ~1e-5 of their reading; double rounding of the smoothing is ~1e-12.
DERIVATIVE_ROUNDING = 1e-8


def temperature_derivatives(t_s, temp_c, smooth_s: float = 10.0,
                            diff_step_s: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(T, dT/dt, d2T/dt2) in deg C, deg C/s, deg C/s^2 on smoothed temperature, by
    3-point backward differences with step h = diff_step_s (docs/methods.md), see
    ``backward_differences``; T(t - h) interpolated on the sample times (held at the
    first sample before the start)."""
    t = np.asarray(t_s, dtype=float)
    ts = smoothed_temperature(t, temp_c, smooth_s)
    h = float(diff_step_s)
    return (ts, *backward_differences(ts, np.interp(t - h, t, ts), np.interp(t - 2 * h, t, ts), h))


def backward_differences(ts, back1, back2, h: float) -> tuple[np.ndarray, np.ndarray]:
    """dT/dt = (3 T(t) - 4 T(t-h) + T(t-2h)) / 2h and d2T/dt2 = (T(t) - 2 T(t-h) + T(t-2h)) / h^2
    from the smoothed temperature now, h and 2h ago (deg C, s), each set to 0 where it is
    below DERIVATIVE_ROUNDING x |T|."""
    tol = DERIVATIVE_ROUNDING * np.maximum(np.abs(ts), 1.0)
    d1 = 3 * ts - 4 * back1 + back2
    d2 = ts - 2 * back1 + back2
    d1 = np.where(np.abs(d1) <= tol, 0.0, d1) / (2 * h)
    d2 = np.where(np.abs(d2) <= tol, 0.0, d2) / (h * h)
    return d1, d2


def thermal_drift(t_s, aux, p, sample_rate_hz=None) -> np.ndarray:
    """K0(T) + K1 dT/dt + K2 d2T/dt2 (deg/h), see ``thermal_drift_from``."""
    return thermal_drift_from(*temperature_derivatives(t_s, aux["temp_c"], p["smooth_s"], p["diff_step_s"]), p)


def thermal_drift_from(ts, d1, d2, p) -> np.ndarray:
    """K0(T) + K1 dT/dt + K2 d2T/dt2 (deg/h) from smoothed T and its derivatives; K1, K2
    take the *_pos values where dT/dt * d2T/dt2 > 0 (heating or cooling accelerates) and
    *_neg elsewhere."""
    pos = d1 * d2 > 0
    k1 = np.where(pos, p["k1_pos"], p["k1_neg"])
    k2 = np.where(pos, p["k2_pos"], p["k2_neg"])
    k0 = np.polynomial.polynomial.polyval(ts, p["k0_poly_dph"]) if p["k0_poly_dph"] else 0.0
    return k0 + k1 * d1 + k2 * d2


def periodic(t_s, aux, p, sample_rate_hz=None) -> np.ndarray:
    """A sin(2 pi t / P + phase) deg/h."""
    return p["amplitude_dph"] * np.sin(2 * np.pi * np.asarray(t_s, float) / p["period_s"] + p["phase_rad"])


def glitches(t_s, aux, p, sample_rate_hz=None) -> np.ndarray:
    """Spikes: each amplitude on the one sample nearest its time (width_s = 0), or on
    every sample in [t_i, t_i + width_s)."""
    t = np.asarray(t_s, dtype=float)
    out = np.zeros(len(t))
    half = 0.5 / _fs(t, sample_rate_hz) if p["width_s"] <= 0 and len(t) else 0.0
    for ti, ai in zip(p["times_s"], p["amplitudes_dph"], strict=True):
        if p["width_s"] > 0:
            out[(t >= ti) & (t < ti + p["width_s"])] += ai
        else:
            out[(t >= ti - half) & (t < ti + half)] += ai
    return out


def bias_step(t_s, aux, p, sample_rate_hz=None) -> np.ndarray:
    """step_dph for t >= t_s (deg/h)."""
    return np.where(np.asarray(t_s, float) >= p["t_s"], p["step_dph"], 0.0)


def rate_ramp(t_s, aux, p, sample_rate_hz=None) -> np.ndarray:
    """slope (deg/h^2) * (t - t0) / 3600 for t >= t0 (deg/h)."""
    dt = np.asarray(t_s, float) - p["t0_s"]
    return np.where(dt >= 0, p["slope_dphh"] * dt / 3600.0, 0.0)


def scale_factor(t_s, aux, p, sample_rate_hz=None) -> np.ndarray:
    """3600 rot_dps (ppm + sign(rot) asym_ppm / 2) 1e-6 (deg/h)."""
    rot = np.asarray(aux["rot_dps"], dtype=float)
    return 3600.0 * rot * (p["ppm"] + np.sign(rot) * p["asym_ppm"] / 2.0) * 1e-6


def warm_up(t_s, aux, p, sample_rate_hz=None) -> np.ndarray:
    """A exp(-(t - t0) / tau) for t >= t0 (deg/h)."""
    dt = np.asarray(t_s, float) - p["t0_s"]
    return np.where(dt >= 0, p["amplitude_dph"] * np.exp(-np.maximum(dt, 0.0) / p["tau_s"]), 0.0)


def feature_values(f: Feature, t_s, channels: dict, smooth_s: float = 10.0, diff_step_s: float = 1.0) -> np.ndarray:
    """The feature ``f`` (fogmon.sim.features) at the sample times ``t_s`` (s) from the
    channels by name (one value per sample): ``d(NAME)/dt`` of the channel smoothed over
    ``smooth_s`` s by 3-point backward differences with step ``diff_step_s`` s
    (``temperature_derivatives``, per second)."""
    x = np.asarray(channels[f.names[0]], dtype=float)
    if f.shape == "linear":
        return x.copy()
    if f.shape == "square":
        return x * x
    if f.shape == "abs":
        return np.abs(x)
    if f.shape == "rate":
        return temperature_derivatives(t_s, x, smooth_s, diff_step_s)[1]
    return x * np.asarray(channels[f.names[1]], dtype=float)


def aux_response(t_s, aux, p, sample_rate_hz=None) -> np.ndarray:
    """offset_dph + sum of coef x feature over the terms (deg/h); every channel a feature
    reads must be in ``aux`` (another axis's rate column too)."""
    t = np.asarray(t_s, dtype=float)
    out = np.full(len(t), p["offset_dph"])
    for term in p["terms"]:
        f = parse_feature(term["feature"])
        missing = [c for c in f.names if c not in aux]
        if missing:
            raise FogmonError(f"effect 'aux_response' term {f.text!r} needs the channel {missing[0]!r}, which the "
                              f"input lacks (have: {', '.join(aux) or 'none'})")
        out += term["coef"] * feature_values(f, t, aux, p["smooth_s"], p["diff_step_s"])
    return out


def vibration_noise(t_s, aux, p) -> np.ndarray:
    """Added ARW level gain * vib_g (deg/sqrt(h))."""
    return p["n_gain_dpsh_per_g"] * np.asarray(aux["vib_g"], dtype=float)


def temperature_noise(t_s, aux, p) -> np.ndarray:
    """Added ARW level gain * (temp_c - t_ref_c) (deg/sqrt(h))."""
    return p["n_gain_dpsh_per_c"] * (np.asarray(aux["temp_c"], dtype=float) - p["t_ref_c"])


MEAN_EFFECTS = {
    "thermal_drift": thermal_drift, "periodic": periodic, "glitches": glitches,
    "bias_step": bias_step, "rate_ramp": rate_ramp, "scale_factor": scale_factor, "warm_up": warm_up,
    "aux_response": aux_response,
}
WHITE_LEVEL_EFFECTS = {"vibration_noise": vibration_noise, "temperature_noise": temperature_noise}


def mean_rate_dph(effect: Effect, t_s, aux: dict, sample_rate_hz: float | None = None) -> np.ndarray:
    """Deterministic rate contribution (deg/h) of a mean-type effect at times t_s (s)."""
    fn = MEAN_EFFECTS[effect.kind]
    if EFFECT_KINDS[effect.kind].aux:
        _aux(effect, aux)
    return np.broadcast_to(fn(np.asarray(t_s, float), aux, effect.params, sample_rate_hz), np.shape(t_s)).astype(float)


def white_level_dpsh(effect: Effect, t_s, aux: dict) -> np.ndarray:
    """Added white-noise level (deg/sqrt(h)) of a white-level effect at each sample."""
    _aux(effect, aux)
    return WHITE_LEVEL_EFFECTS[effect.kind](t_s, aux, effect.params)


def noise_generator(effect: Effect, sample_rate_hz: float, rng: np.random.Generator):
    """Stateful generator of a noise-type effect (``markov``, ``lowpass_noise``, ``outliers``,
    ``vibration_lines``)."""
    p = effect.params
    if effect.kind == "outliers":
        return OutlierSpikes(p, sample_rate_hz, rng)
    if effect.kind == "vibration_lines":
        return NarrowbandLines(p, sample_rate_hz, rng)
    if effect.kind == "lowpass_noise":
        return LowpassNoise(p["sigma_dph"], p["cutoff_hz"], p["order"], sample_rate_hz, rng)
    return GaussMarkov(p["sigma_dph"], p["tau_c_s"], sample_rate_hz, rng)


class OutlierSpikes:
    """``outliers``: a Poisson process of one-sample spikes on the sample grid (rate_per_h
    per hour), |amplitude| (deg/h) drawn by interpolating the quantile function given by
    (quantile_probs, amplitude_quantiles_dph), positive with probability
    positive_fraction. Three uniforms per sample, so the numbers do not depend on the
    chunking."""

    def __init__(self, params: dict, sample_rate_hz: float, rng: np.random.Generator):
        self.p_hit = params["rate_per_h"] / 3600.0 / sample_rate_hz
        if self.p_hit > 1.0:
            raise FogmonError(f"outliers: rate_per_h {params['rate_per_h']:g} is more than one per sample at "
                              f"{sample_rate_hz:g} Hz")
        self.probs = np.asarray(params["quantile_probs"], dtype=float)
        self.quantiles = np.asarray(params["amplitude_quantiles_dph"], dtype=float)
        self.positive = params["positive_fraction"]
        self.rng = rng

    def generate(self, n: int) -> np.ndarray:
        u = self.rng.random((n, 3))
        hit = u[:, 0] < self.p_hit
        amp = np.interp(u[hit, 1], self.probs, self.quantiles)
        out = np.zeros(n)
        out[hit] = np.where(u[hit, 2] < self.positive, amp, -amp)
        return out


def lookback_s(effect: Effect) -> float:
    """History (s) a mean-type effect needs before a chunk to be exact on it."""
    if effect.kind == "thermal_drift" or (effect.kind == "aux_response" and any(
            parse_feature(t["feature"]).shape == "rate" for t in effect.params["terms"])):
        return effect.params["smooth_s"] + 2.0 * effect.params["diff_step_s"]
    return 0.0


class NarrowbandLines:
    """A ``vibration_lines`` effect: the sum of its lines (noise.NarrowbandLine), each
    with its own random stream spawned from the effect's."""

    def __init__(self, params: dict, sample_rate_hz: float, rng: np.random.Generator):
        p = params
        self.lines = [NarrowbandLine(f, s, bw, sample_rate_hz, r) for f, s, bw, r in
                      zip(p["freq_hz"], p["sigma_dph"], p["bandwidth_hz"], rng.spawn(len(p["freq_hz"])), strict=True)]

    def generate(self, n: int) -> np.ndarray:
        out = np.zeros(n)
        for line in self.lines:
            out += line.generate(n)
        return out


class BandwidthFilter:
    """The sensor's own low-pass: Butterworth (cutoff_hz, order) as second-order
    sections, or FIR ``taps``; stateful across chunks, started in steady state for the
    first input value (no start-up transient on a constant bias)."""

    def __init__(self, params: dict, sample_rate_hz: float):
        if params["taps"]:
            self.taps = np.asarray(params["taps"], dtype=float)
            self.sos = None
        else:
            if params["cutoff_hz"] >= sample_rate_hz / 2:
                raise FogmonError(f"bandwidth: cutoff_hz {params['cutoff_hz']:g} must be below "
                                  f"the Nyquist frequency {sample_rate_hz / 2:g} Hz")
            self.sos = lowpass_filter(params["cutoff_hz"], params["order"], sample_rate_hz)
        self._zi: np.ndarray | None = None

    def apply(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if not len(x):
            return x.copy()
        if self.sos is not None:
            if self._zi is None:
                self._zi = sosfilt_zi(self.sos) * x[0]
            y, self._zi = sosfilt(self.sos, x, zi=self._zi)
        else:
            if self._zi is None:
                self._zi = lfilter_zi(self.taps, [1.0]) * x[0] if len(self.taps) > 1 else np.zeros(0)
            if len(self.taps) > 1:
                y, self._zi = lfilter(self.taps, [1.0], x, zi=self._zi)
            else:
                y = self.taps[0] * x
        return y
