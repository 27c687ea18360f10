"""IEEE Std 952 noise generators, exact at any sample rate fs (tau0 = 1/fs), all in deg/h.

Every generator is a small stateful object with ``generate(n) -> ndarray`` that
continues the same realization chunk after chunk: generating N samples in one call or
in any split of calls gives bit-identical output (each generator owns its random
stream; lfilter states carry over). This is what keeps a 24 h run at 1 kHz in bounded
memory while staying one reproducible realization per seed.

- Q (quantization): white angle noise theta_k ~ N(0, Q^2) arcsec,
  rate_k = (theta_k - theta_{k-1}) / tau0 (1 arcsec/s = 1 deg/h); sigma = sqrt(3) Q / tau
  exactly for every m.
- N (angle random walk): white rate, per-sample std 60 N sqrt(fs) deg/h; sigma = 60 N / sqrt(tau).
- B (bias instability, flicker): a sum of independent first-order Gauss-Markov terms
  with correlation times log-spaced by ``ratio`` (default 2) from tau0/4 to ``tau_hi_s``,
  each of variance B^2 ln(ratio) / pi. Its PSD approximates h_-1 / f with
  h_-1 = B^2 / pi, the 0.664 B floor (sqrt(2 ln 2 / pi) B). Chosen over Kasdin's FFT
  filter because it streams in O(terms) per sample with no kernel truncation; the exact
  ADEV of this process (``flicker_adev_exact``) stays within 1.0 % of 0.664 B for
  20 tau0 <= tau <= tau_hi_s / 100 (ratio 2), and sits at 0.86 B at tau = tau0 (the
  discrete Kasdin process gives 0.798 B there; both exceed the floor over the first
  few tau0, as expected).
- K (rate random walk): cumulative sum of steps with std (K/60) sqrt(tau0);
  sigma = (K/60) sqrt(tau/3).
- R (rate ramp): (R/3600) (t - t_start); sigma = R tau / (3600 sqrt(2)).
- Gauss-Markov (``markov`` effect): exact sampled AR(1), x_k = a x_{k-1} + sqrt(1-a^2) sigma e_k,
  a = exp(-tau0/tau_c), started in its stationary distribution.
- Low-pass noise (``lowpass_noise`` effect): white noise through a Butterworth low-pass
  (:func:`lowpass_filter`, the ``bandwidth`` effect's filter), scaled to sigma rms,
  started stationary by a burn-in as long as the impulse response it keeps.
- Narrowband line (``vibration_lines`` effect): white noise through a 4-pole
  Butterworth band-pass (-3 dB edges f -+ bw/2), scaled to sigma rms; each line has its
  own random stream.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.signal import butter, lfilter, sos2zpk, sosfilt, sosfreqz

from fogmon.davar.theory import FLICKER_FACTOR

#: flat flicker ADEV floor per unit B: sqrt(2 ln 2 / pi) = 0.6643
FLICKER_FLOOR = math.sqrt(FLICKER_FACTOR)


def white_std_dph(N_dpsh, sample_rate_hz: float):
    """Per-sample standard deviation (deg/h) of white rate noise of ARW N (deg/sqrt(h))."""
    return 60.0 * np.asarray(N_dpsh, dtype=float) * math.sqrt(sample_rate_hz)


class WhiteAngle:
    """Quantization noise Q (arcsec) as differenced white angle noise, deg/h."""

    def __init__(self, Q_arcsec: float, sample_rate_hz: float, rng: np.random.Generator):
        self.Q, self.sample_rate_hz, self.rng = float(Q_arcsec), float(sample_rate_hz), rng
        self._last = self.Q * rng.standard_normal()

    def generate(self, n: int) -> np.ndarray:
        theta = self.Q * self.rng.standard_normal(n)
        prev = np.concatenate(([self._last], theta[:-1])) if n else theta
        if n:
            self._last = theta[-1]
        return (theta - prev) * self.sample_rate_hz


class WhiteRate:
    """White rate noise with a per-sample ARW level N (deg/sqrt(h), scalar or array):
    the same unit-normal sequence scaled by 60 N sqrt(fs), so N may vary over time."""

    def __init__(self, sample_rate_hz: float, rng: np.random.Generator):
        self.sample_rate_hz, self.rng = float(sample_rate_hz), rng

    def generate(self, n: int, N_dpsh=1.0) -> np.ndarray:
        return white_std_dph(N_dpsh, self.sample_rate_hz) * self.rng.standard_normal(n)


class GaussMarkov:
    """First-order Gauss-Markov rate noise (std sigma_dph deg/h, correlation time
    tau_c_s s), exact sampled AR(1) started stationary."""

    def __init__(self, sigma_dph: float, tau_c_s: float, sample_rate_hz: float, rng: np.random.Generator):
        self.sigma = float(sigma_dph)
        self.a = math.exp(-1.0 / (sample_rate_hz * tau_c_s))
        self.b = self.sigma * math.sqrt(-math.expm1(-2.0 / (sample_rate_hz * tau_c_s)))
        self.rng = rng
        x_prev = self.sigma * rng.standard_normal()
        self._zi = np.array([self.a * x_prev])

    def generate(self, n: int) -> np.ndarray:
        if n == 0:  # lfilter returns a wrong final state for empty input
            return np.zeros(0)
        e = self.rng.standard_normal(n)
        y, self._zi = lfilter([self.b], [1.0, -self.a], e, zi=self._zi)
        return y


class NarrowbandLine:
    """Narrowband random vibration (``vibration_lines``, one line): white noise through
    the band-pass of :func:`line_filter` (-3 dB band ``freq_hz`` +- ``bandwidth_hz`` / 2),
    scaled to ``sigma_dph`` rms (deg/h); started in steady state by a burn-in of
    LINE_BURN_IN envelope time constants 1 / (pi bandwidth_hz)."""

    def __init__(self, freq_hz: float, sigma_dph: float, bandwidth_hz: float, sample_rate_hz: float,
                 rng: np.random.Generator):
        self.sos = line_filter(freq_hz, bandwidth_hz, sample_rate_hz)
        self.scale = float(sigma_dph) / math.sqrt(line_noise_gain(freq_hz, bandwidth_hz, sample_rate_hz))
        self.rng = rng
        burn = int(math.ceil(LINE_BURN_IN * sample_rate_hz / (math.pi * bandwidth_hz))) + 2
        _, self._zi = sosfilt(self.sos, rng.standard_normal(burn), zi=np.zeros((len(self.sos), 2)))

    def generate(self, n: int) -> np.ndarray:
        if n == 0:
            return np.zeros(0)
        y, self._zi = sosfilt(self.sos, self.rng.standard_normal(n), zi=self._zi)
        return self.scale * y


def lowpass_filter(cutoff_hz: float, order: int, sample_rate_hz: float) -> np.ndarray:
    """Second-order sections of the Butterworth low-pass of ``order`` with its -3 dB
    point at ``cutoff_hz`` (below the Nyquist frequency): the ``bandwidth`` effect's
    filter and the ``lowpass_noise`` effect's."""
    return butter(int(order), cutoff_hz, fs=sample_rate_hz, output="sos")


#: A low-pass's impulse response is followed until the energy it has left is below this
#: fraction of its total (the burn-in of LowpassNoise, the support of lowpass_acf).
LOWPASS_TAIL = 1e-15


def lowpass_impulse(cutoff_hz: float, order: int, sample_rate_hz: float) -> np.ndarray:
    """Impulse response of :func:`lowpass_filter` up to where its remaining energy is
    below LOWPASS_TAIL of the total (bounded by its slowest pole's radius r: the tail
    from sample L on decays as r^L, with a margin for the other poles)."""
    sos = lowpass_filter(cutoff_hz, order, sample_rate_hz)
    r = float(np.max(np.abs(sos2zpk(sos)[1])))
    n = int(math.ceil(math.log(LOWPASS_TAIL) / (2.0 * math.log(r)))) + 16 * int(order) + 16
    impulse = np.zeros(n)
    impulse[0] = 1.0
    return sosfilt(sos, impulse)


def lowpass_acf(sigma_dph: float, cutoff_hz: float, order: int, sample_rate_hz: float) -> np.ndarray:
    """Autocovariance ((deg/h)^2) at lags 0, 1, ... of ``lowpass_noise`` (white noise through
    :func:`lowpass_filter`, variance sigma^2); 0 beyond the lags returned."""
    h = lowpass_impulse(cutoff_hz, order, sample_rate_hz)
    r = np.correlate(h, h, mode="full")[len(h) - 1:]
    return sigma_dph ** 2 * r / r[0]


def lowpass_adev_exact(m, sigma_dph: float, cutoff_hz: float, order: int, sample_rate_hz: float) -> np.ndarray:
    """Exact overlapping-ADEV expectation (deg/h) of ``lowpass_noise`` at averaging factors
    m: AVAR = (4 V(m) - V(2m)) / (2 m^2), V(m) = m r_0 + 2 sum_{k<m} (m - k) r_k the
    variance of a sum of m samples (r: :func:`lowpass_acf`)."""
    r = lowpass_acf(sigma_dph, cutoff_hz, order, sample_rate_hz)
    k = np.arange(len(r), dtype=float)
    s0, s1 = np.cumsum(r[1:]), np.cumsum(k[1:] * r[1:])

    def var_sum(mm: np.ndarray) -> np.ndarray:
        j = np.minimum(mm, len(r)) - 2  # index of lag min(mm, len(r)) - 1 in s0, s1
        tail = np.where(j >= 0, mm * s0[np.maximum(j, 0)] - s1[np.maximum(j, 0)], 0.0)
        return mm * r[0] + 2.0 * tail

    m = np.asarray(m, dtype=np.int64)
    return np.sqrt(np.maximum((4.0 * var_sum(m) - var_sum(2 * m)) / (2.0 * m.astype(float) ** 2), 0.0))


class LowpassNoise:
    """``lowpass_noise``: white noise through :func:`lowpass_filter`, scaled to
    ``sigma_dph`` rms (deg/h), started stationary (a burn-in as long as the impulse
    response :func:`lowpass_impulse` keeps)."""

    def __init__(self, sigma_dph: float, cutoff_hz: float, order: int, sample_rate_hz: float,
                 rng: np.random.Generator):
        self.sos = lowpass_filter(cutoff_hz, order, sample_rate_hz)
        h = lowpass_impulse(cutoff_hz, order, sample_rate_hz)
        self.scale = float(sigma_dph) / math.sqrt(float(np.sum(h * h)))
        self.rng = rng
        _, self._zi = sosfilt(self.sos, rng.standard_normal(len(h)), zi=np.zeros((len(self.sos), 2)))

    def generate(self, n: int) -> np.ndarray:
        if n == 0:
            return np.zeros(0)
        y, self._zi = sosfilt(self.sos, self.rng.standard_normal(n), zi=self._zi)
        return self.scale * y


def lowpass_psd(omega: np.ndarray, sigma_dph: float, cutoff_hz: float, order: int, sample_rate_hz: float
                ) -> np.ndarray:
    """Two-sided PSD ((deg/h)^2 per unit normalized frequency) of ``lowpass_noise`` at
    angular normalized frequencies ``omega``: sigma^2 |H|^2 / sum of h^2."""
    h = lowpass_impulse(cutoff_hz, order, sample_rate_hz)
    return sigma_dph ** 2 / float(np.sum(h * h)) * line_gain2(lowpass_filter(cutoff_hz, order, sample_rate_hz), omega)


#: burn-in of a narrowband line generator, in envelope time constants 1 / (pi bandwidth)
LINE_BURN_IN = 20.0


def line_filter(freq_hz: float, bandwidth_hz: float, sample_rate_hz: float) -> np.ndarray:
    """Second-order sections of a ``vibration_lines`` line: the 4-pole Butterworth
    band-pass (scipy.signal.butter order 2, btype "bandpass") whose -3 dB edges are
    freq_hz -+ bandwidth_hz / 2: gain 1 in the band, falling as 1/f^2 (power 1/f^4)
    outside it, 0 at DC and Nyquist."""
    return butter(2, [freq_hz - bandwidth_hz / 2.0, freq_hz + bandwidth_hz / 2.0], btype="bandpass",
                  fs=sample_rate_hz, output="sos")


def line_gain2(sos: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """|H|^2 of a line's band-pass at angular normalized frequencies ``omega`` (rad/sample)."""
    _, h = sosfreqz(sos, worN=np.asarray(omega, dtype=float))
    return np.abs(h) ** 2


def line_noise_gain(freq_hz: float, bandwidth_hz: float, sample_rate_hz: float) -> float:
    """Output variance of a line's band-pass for unit-variance white input,
    (1/pi) * integral over 0..pi of |H|^2 (trapezoid on a grid of 2000 points across
    the band +- 20 bandwidths and 1000 log-spaced points elsewhere: well under 0.1 %)."""
    sos = line_filter(freq_hz, bandwidth_hz, sample_rate_hz)
    w0, dw = 2 * math.pi * freq_hz / sample_rate_hz, 2 * math.pi * bandwidth_hz / sample_rate_hz
    near = np.linspace(max(w0 - 20 * dw, 1e-9), min(w0 + 20 * dw, math.pi), 2000)
    w = np.unique(np.concatenate((near, np.geomspace(1e-9, math.pi, 1000), [math.pi])))
    return float(np.trapezoid(line_gain2(sos, w), w) / math.pi)


def line_psd(
    omega: np.ndarray, sample_rate_hz: float, freq_hz: float, sigma_dph: float, bandwidth_hz: float
) -> np.ndarray:
    """Two-sided PSD ((deg/h)^2 per unit normalized frequency, sum over the n DFT bins / n
    = variance) of one narrowband line at angular normalized frequencies ``omega``."""
    sos = line_filter(freq_hz, bandwidth_hz, sample_rate_hz)
    return sigma_dph ** 2 / line_noise_gain(freq_hz, bandwidth_hz, sample_rate_hz) * line_gain2(sos, omega)


def flicker_taus(sample_rate_hz: float, tau_hi_s: float, ratio: float = 2.0) -> np.ndarray:
    """Correlation times (s) of the Gauss-Markov terms of the flicker generator."""
    tau_lo = 0.25 / sample_rate_hz
    k = int(math.ceil(math.log(max(tau_hi_s / tau_lo, ratio)) / math.log(ratio))) + 1
    return tau_lo * ratio ** np.arange(k)


def default_flicker_tau_hi_s(sample_rate_hz: float, duration_s: float | None) -> float:
    """Longest flicker correlation time: 10x the duration when known (keeps the floor
    within 0.1 % up to duration/10), else 1e9 tau0."""
    return 10.0 * duration_s if duration_s else 1e9 / sample_rate_hz


class Flicker:
    """Bias-instability (flicker) rate noise of coefficient B (deg/h): sum of
    Gauss-Markov terms, see the module docstring."""

    def __init__(self, B_dph: float, sample_rate_hz: float, rng: np.random.Generator,
                 tau_hi_s: float | None = None, ratio: float = 2.0):
        tau_hi_s = tau_hi_s or default_flicker_tau_hi_s(sample_rate_hz, None)
        self.taus_s = flicker_taus(sample_rate_hz, tau_hi_s, ratio)
        sigma = float(B_dph) * math.sqrt(math.log(ratio) / math.pi)
        self.terms = [GaussMarkov(sigma, tc, sample_rate_hz, r)
                      for tc, r in zip(self.taus_s, rng.spawn(len(self.taus_s)), strict=True)]

    def generate(self, n: int) -> np.ndarray:
        out = np.zeros(n)
        for term in self.terms:
            out += term.generate(n)
        return out


class RandomWalk:
    """Rate random walk K (deg/h/sqrt(h)): steps of std (K/60) sqrt(tau0), from 0."""

    def __init__(self, K_dphsh: float, sample_rate_hz: float, rng: np.random.Generator):
        self.step = float(K_dphsh) / 60.0 * math.sqrt(1.0 / sample_rate_hz)
        self.rng = rng
        self._zi = np.zeros(1)

    def generate(self, n: int) -> np.ndarray:
        if n == 0:
            return np.zeros(0)
        # a sequential recursion (not cumsum) so any chunking gives identical bits
        x, self._zi = lfilter([1.0], [1.0, -1.0], self.step * self.rng.standard_normal(n), zi=self._zi)
        return x


def ramp_dph(R_dphh: float, t_rel_s) -> np.ndarray:
    """Rate ramp R (deg/h^2) at times t_rel_s since the start: (R/3600) t deg/h."""
    return float(R_dphh) / 3600.0 * np.asarray(t_rel_s, dtype=float)


def ar1_adev_exact(m, sigma_dph: float, tau_c_s: float, sample_rate_hz: float) -> np.ndarray:
    """Exact overlapping-ADEV expectation (deg/h) of the sampled AR(1) process of
    GaussMarkov at averaging factors m:
    AVAR = s^2 [m (1 - a^2) - a (1 - a^m)(3 - a^m)] / (m^2 (1 - a)^2), a = exp(-tau0/tau_c).
    Where m tau0/tau_c < 1e-4 that difference cancels, and the random-walk limit
    q (2 m^2 + 1) / (6 m), q = s^2 (1 - a^2), is used (relative error < 1e-4)."""
    m = np.asarray(m, dtype=float)
    x = 1.0 / (sample_rate_hz * tau_c_s)
    a = math.exp(-x)
    u = -math.expm1(-x)
    am = np.exp(-m * x)
    s2 = sigma_dph ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        exact = s2 * (m * u * (1.0 + a) - a * (1.0 - am) * (3.0 - am)) / (m * m * u * u)
    walk = s2 * u * (1.0 + a) * (2.0 * m * m + 1.0) / (6.0 * m)
    return np.sqrt(np.maximum(np.where(m * x < 1e-4, walk, exact), 0.0))


def flicker_adev_exact(m, B_dph: float, sample_rate_hz: float, tau_hi_s: float, ratio: float = 2.0) -> np.ndarray:
    """Exact ADEV expectation (deg/h) of the Flicker generator at averaging factors m."""
    sigma = B_dph * math.sqrt(math.log(ratio) / math.pi)
    return np.sqrt(
        sum(ar1_adev_exact(m, sigma, tc, sample_rate_hz) ** 2 for tc in flicker_taus(sample_rate_hz, tau_hi_s, ratio))
    )
