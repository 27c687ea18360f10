"""Simulations of a model's stochastic part on a record's sample grid, for explain's
bootstrap (docs/explain.md, "Bootstrap cost"): the same law as ``fogmon.sim`` (every
term Gaussian and exact, the noise-type effects by the simulator's own generators, the
``bandwidth`` filters applied the same way), drawn in O(n log n) with a small constant.

The stationary Gaussian terms - white N (when no white-level effect varies it), Q
(differenced white angle), the flicker B (the simulator's sum of Gauss-Markov terms)
and ``markov`` effects - are one process with a known autocovariance r_k, drawn at once
by circulant embedding (Dietrich & Newsam 1997, SIAM J. Sci. Comput. 18, 1088): the
autocovariance wrapped onto a circle of L >= 2 (n - 1) lags has non-negative
eigenvalues lambda (its DFT) because every term's r_k is a non-negative, decreasing,
convex sequence (white: one lag; AR(1): a^k) or has a non-negative spectrum on the
circle itself (Q: 2 - 2 cos w); then irfft(sqrt(lambda L) x complex normal) has exactly
the covariance r on its first n samples. The simulator's flicker runs 20-30 AR(1)
filters with a normal draw each per sample; here one FFT of 2n does them all (about
30x less work at 1e6 samples). That FFT runs in single precision (3x faster): its
rounding, 1e-7 of the terms' total rms, is far below anything the map resolves. The
rate random walk K is a cumulative sum from 0, a white level that varies with an aux
channel scales its own normal sequence, and the other noise-type effects
(``lowpass_noise``, ``vibration_lines``, ``outliers``) come from
``fogmon.sim.effects.noise_generator``. Different numbers than ``fogmon sim`` for a seed,
the same distribution.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import fft as sfft

from fogmon.explain.fitting import noise_psd, rfft_omega
from fogmon.sim import effects as fx
from fogmon.sim.model import EFFECT_KINDS, SensorModel
from fogmon.sim.noise import default_flicker_tau_hi_s, flicker_taus, white_std_dph

#: an AR(1) autocovariance is followed until a^k falls below this (exp(-40) = 4e-18 of its variance)
AR1_TAIL = 40.0


class Replicas:
    """Draws of the stochastic model ``stoch`` (bias, R and mean-type effects already
    left out, ``explainer.stochastic_part``) on a grid of ``n`` samples at
    ``sample_rate_hz`` with sample times ``t_s`` (s), gap-filled ``aux`` channels (for the
    white-level effects) and ``valid`` mask: ``draw(seed)`` is one replicate (deg/h, NaN
    where not valid)."""

    def __init__(self, stoch: SensorModel, t_s: np.ndarray, aux: dict, valid: np.ndarray):
        self.stoch, self.t_s, self.aux, self.valid = stoch, t_s, aux, valid
        self.n = n = len(t_s)
        fs = self.sample_rate_hz = float(stoch.sample_rate_hz)
        nz = stoch.noise
        levels = [e for e in stoch.effects if EFFECT_KINDS[e.kind].nature == "white_level"]
        #: per-sample white std (deg/h) when a white-level effect varies it, else None (N is in the spectrum)
        self.white_sd: np.ndarray | None = None
        ar1 = [(e.params["sigma_dph"], e.params["tau_c_s"]) for e in stoch.effects if e.kind == "markov"]
        if nz.B_dph > 0:
            sig = float(nz.B_dph) * math.sqrt(math.log(2.0) / math.pi)
            ar1 += [(sig, float(tc)) for tc in flicker_taus(fs, default_flicker_tau_hi_s(fs, n / fs))]
        white_var = float(white_std_dph(nz.N_dpsh, fs)) ** 2
        if levels:
            level = np.full(n, nz.N_dpsh)
            for e in levels:
                level = level + fx.white_level_dpsh(e, t_s, aux)
            self.white_sd = white_std_dph(np.maximum(level, 0.0), fs)
            white_var = 0.0
        q2 = (float(nz.Q_arcsec) * fs) ** 2
        #: the law's terms as ``law_psd`` reads them
        self.ar1, self.Q_arcsec, self.K_dphsh = ar1, float(nz.Q_arcsec), float(nz.K_dphsh)
        self.white_var_mean = white_var if self.white_sd is None else float(np.mean(self.white_sd ** 2))
        self.L = L = _even_fast_len(max(2 * (n - 1), 2))
        self.sqrt_lambda = _embedding_sqrt_eigenvalues(L, fs, white_var, q2, ar1)
        self.k_step = float(nz.K_dphsh) / 60.0 * math.sqrt(1.0 / fs)
        self.others = [e for e in stoch.effects if EFFECT_KINDS[e.kind].nature == "noise" and e.kind != "markov"]
        self.filters = [e for e in stoch.effects if EFFECT_KINDS[e.kind].nature == "filter"]
        self._buffers: dict[str, np.ndarray] = {}
        self._law_psd: np.ndarray | None = None

    def draw(self, seed: int) -> np.ndarray:
        """One replicate (deg/h, NaN where not valid), reproducible from ``seed``."""
        n, L = self.n, self.L
        streams = [np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(3 + len(self.others))]
        if self.sqrt_lambda is not None:
            normals = self._buffer("normals", 2 * len(self.sqrt_lambda))
            streams[0].standard_normal(out=normals, dtype=np.float32)
            spec = normals.view(np.complex64)
            spec[0] = math.sqrt(2.0) * spec[0].real     # DC and Nyquist: real, full variance
            spec[-1] = math.sqrt(2.0) * spec[-1].real
            spec *= self.sqrt_lambda
            rate = np.fft.irfft(spec, L, out=self._buffer("series", L))[:n].astype(np.float64)
        else:
            rate = np.zeros(n)
        if self.white_sd is not None:
            rate += self.white_sd * streams[1].standard_normal(n)
        if self.k_step:
            rate += np.cumsum(self.k_step * streams[2].standard_normal(n))
        for e, rng in zip(self.others, streams[3:], strict=True):
            rate += fx.noise_generator(e, self.sample_rate_hz, rng).generate(n)
        for e in self.filters:
            rate = fx.BandwidthFilter(e.params, self.sample_rate_hz).apply(rate)
        rate[~self.valid] = np.nan
        return rate

    def functional_cov(self, a: np.ndarray) -> np.ndarray:
        """The exact covariance (p x p) of the functionals a @ r of a draw r (a: p x n, 0
        where not valid) under the Gaussian terms of the law: the stationary ones through
        the circulant embedding the draws use (a zero-padded to L: a' Sigma a = sum over
        the L bins of lambda |A|^2 / L), a white level that varies (sum a^2 sd^2)
        and the rate random walk (a cumulative sum from 0: k_step^2 sum_s (sum_t>=s a_t)^2).
        The other noise-type effects and the bandwidth filters are left out."""
        a = np.atleast_2d(np.asarray(a, dtype=np.float64))
        V = np.zeros((a.shape[0], a.shape[0]))
        if self.sqrt_lambda is not None:
            Af = np.fft.rfft(a, self.L, axis=1)
            mult = np.full(Af.shape[1], 2.0)
            mult[0] = mult[-1] = 1.0
            lam = self.sqrt_lambda.astype(np.float64) ** 2 * (2.0 / self.L)  # float32's 1e-7 is plenty here
            V += ((Af * (mult * lam)) @ Af.conj().T).real / self.L
        if self.white_sd is not None:
            V += (a * self.white_sd ** 2) @ a.T
        if self.k_step:
            tails = np.cumsum(a[:, ::-1], axis=1)[:, ::-1]
            V += self.k_step ** 2 * (tails @ tails.T)
        return V

    def law_psd(self) -> np.ndarray:
        """The PSD ((deg/h)^2 per unit normalized frequency) of the terms ``functional_cov``
        counts at the rfft bins of the grid, as a Whittle fit takes it (``fitting.noise_psd``;
        a varying white level at its mean square); +inf at bin 0. Computed once."""
        if self._law_psd is None:
            S = noise_psd(rfft_omega(self.n), self.sample_rate_hz, self.Q_arcsec, 0.0, self.K_dphsh, tuple(self.ar1))
            self._law_psd = S + self.white_var_mean
        return self._law_psd

    def _buffer(self, name: str, size: int) -> np.ndarray:
        """A float32 work array kept between draws (not pickled): the allocations of a
        draw cost more than its arithmetic at 1e7 samples."""
        if name not in self._buffers:
            self._buffers[name] = np.empty(size, np.float32)
        return self._buffers[name]

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_buffers": {}, "_law_psd": None}


def _even_fast_len(m: int) -> int:
    """The smallest even length >= m whose real FFT is fast (2^a 3^b 5^c ...)."""
    L = sfft.next_fast_len(m, real=True)
    while L % 2:
        L = sfft.next_fast_len(L + 1, real=True)
    return L


def _embedding_sqrt_eigenvalues(L: int, sample_rate_hz: float, white_var: float, q2: float,
                                ar1: list[tuple[float, float]]) -> np.ndarray | None:
    """sqrt(lambda L / 2) (float32) at the L/2 + 1 rfft bins of the circulant embedding (length L)
    of the autocovariance white_var delta_k + q2 (2 delta_k - delta_|k|=1) + sum of
    sigma^2 a^|k| (``ar1``: (sigma deg/h, tau_c s) each, a = exp(-tau0 / tau_c)); None
    when all are 0. With these, irfft(sqrt_lambda (x + i y), L), x and y standard
    normal (DC and Nyquist real with variance 2), has the autocovariance on its first
    L/2 + 1 lags."""
    if white_var <= 0 and q2 <= 0 and not ar1:
        return None
    half = L // 2
    c = np.zeros(half + 1)
    c[0] += white_var + 2.0 * q2
    if half >= 1:
        c[1] -= q2
    for sigma, tau_c in ar1:
        x = 1.0 / (sample_rate_hz * tau_c)
        m = min(half + 1, int(math.ceil(AR1_TAIL / x)) + 1)
        c[:m] += sigma ** 2 * np.exp(-x * np.arange(m))
    full = np.concatenate((c, c[half - 1:0:-1]))  # c_0 .. c_L/2, c_L/2-1 .. c_1
    lam = sfft.rfft(full).real
    return np.sqrt(np.maximum(lam, 0.0) * L / 2.0).astype(np.float32)
