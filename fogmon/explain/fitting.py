"""Frequency-domain generalized least squares (Whittle) for effects that are linear in
their coefficients, with the noise PSD of the sensor model as weights.

For a residual y (deg/h, n samples) and design columns X (n x p), with Y_k, X_k their
DFTs and S_k the two-sided noise PSD in (deg/h)^2 per unit normalized frequency
(sum_k S_k / n = per-sample variance), the Whittle chi-square is

    chi2(beta) = sum_{k != 0} |Y_k - X_k beta|^2 / (n S_k)

summed over all n bins (rfft bins weighted 2, the Nyquist bin 1). The DC bin is left
out: the recording's bias is unknown. Minimizing gives beta = A^-1 b with
A = Re(X^H W X), b = Re(X^H W Y); cov(beta) = A^-1; the drop in chi2 is b^T A^-1 b,
which is chi-square with p degrees of freedom when the effect is absent (a
likelihood-ratio statistic).

The model's PSD is calibrated to the recording in octave bands holding >= 32 bins
(band median of |Y_k|^2 / (n S_k), divided by ln 2, the median of a unit exponential):
a wrong white-noise level or an unmodelled noise hump then cannot masquerade as a
deterministic effect. Bands below 32 bins (the slowest frequencies, where drifts live)
keep the lowest calibrated band's factor; there, a mean-type effect is judged against the
noise its own residual shows (:func:`low_band_flicker`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.optimize import minimize_scalar

MIN_BAND_BINS = 32


def rfft_omega(n: int) -> np.ndarray:
    """Angular normalized frequencies 2 pi k / n of the rfft bins (rad/sample)."""
    return 2.0 * np.pi * np.arange(n // 2 + 1) / n


def noise_psd(omega: np.ndarray, sample_rate_hz: float, Q_arcsec: float = 0.0, N_dpsh: float = 0.0,
              K_dphsh: float = 0.0, markov: tuple[tuple[float, float], ...] = ()) -> np.ndarray:
    """Two-sided PSD in (deg/h)^2 per unit normalized frequency at angular normalized
    frequencies ``omega`` (rad/sample) for IEEE-952 Q (arcsec), N (deg/sqrt(h)),
    K (deg/h/sqrt(h)) and Gauss-Markov terms ``markov`` = ((sigma_dph, tau_c_s), ...)
    (flicker B enters as a sum of such terms, see :func:`model_psd`). +inf at omega 0."""
    w = np.asarray(omega, dtype=np.float64)
    s2 = np.sin(w / 2.0) ** 2
    with np.errstate(divide="ignore"):
        S = np.full(len(w), (60.0 * N_dpsh) ** 2 * sample_rate_hz)
        S += 4.0 * s2 * (Q_arcsec * sample_rate_hz) ** 2
        if K_dphsh > 0:
            S += (K_dphsh / 60.0) ** 2 / sample_rate_hz / (4.0 * s2)
        for sigma, tau_c in markov:
            S += markov_psd(w, sample_rate_hz, sigma, tau_c, s2)
    S[w == 0] = np.inf
    return np.maximum(S, 1e-300)


def markov_psd(omega: np.ndarray, sample_rate_hz: float, sigma_dph: float, tau_c_s: float,
               sin2_half: np.ndarray | None = None) -> np.ndarray:
    """PSD of the sampled first-order Gauss-Markov process (AR(1), a = exp(-tau0/tau_c)):
    sigma^2 (1 - a^2) / |1 - a e^(-i omega)|^2, the denominator as (1 - a)^2 + 4 a
    sin^2(omega / 2) (``sin2_half``, when the caller has it)."""
    x = 1.0 / (sample_rate_hz * tau_c_s)
    a, u = math.exp(-x), -math.expm1(-x)  # u = 1 - a, exact for a near 1
    s2 = np.sin(np.asarray(omega) / 2.0) ** 2 if sin2_half is None else sin2_half
    return sigma_dph ** 2 * u * (1.0 + a) / (u * u + 4.0 * a * s2)


def calibrate_psd(S: np.ndarray, Yf: np.ndarray, n: int) -> np.ndarray:
    """``S`` scaled per octave band of bins to the periodogram |Y_k|^2 / n (band median /
    ln 2); bands with fewer than MIN_BAND_BINS bins use the nearest calibrated band."""
    ratio = (np.abs(Yf) ** 2 / n) / S
    nb = len(S)
    edges = [1]
    while edges[-1] < nb:
        edges.append(min(nb, edges[-1] * 2))
    factors = np.ones(nb)
    first_ok = None
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        if hi - lo < MIN_BAND_BINS:
            continue
        f = float(np.median(ratio[lo:hi])) / math.log(2.0)
        f = min(max(f, 1e-3), 1e3)
        factors[lo:hi] = f
        if first_ok is None:
            first_ok = (lo, f)
    if first_ok is not None:
        factors[1:first_ok[0]] = first_ok[1]
    out = S * factors
    out[0] = np.inf
    return out


#: A flicker (1/f) excess below the first calibrated band joins the PSD only when it raises
#: the Whittle log-likelihood of those bins by more than this (likelihood ratio; the 99 %
#: point of chi-square with 1 degree of freedom, as a baseline noise term's): a null
#: residual's chance low-frequency scatter then rarely costs a real effect its power.
LOW_FLICKER_CHI2 = 6.63


def low_band_flicker(S: np.ndarray, Rf: np.ndarray, n: int) -> np.ndarray:
    """``S`` (calibrated, :func:`calibrate_psd`) with the residual's own flicker excess
    added below its first calibrated band: the bins 1..K-1 (K = MIN_BAND_BINS) get
    b S_K K / k, a 1/f continuation of the PSD level at bin K, with b >= 0 fitted by
    the Whittle likelihood of the residual's DFT ``Rf`` there; ``S`` itself when the
    excess is not significant (LOW_FLICKER_CHI2) or the record has no calibrated band.
    Those bins are where drifts, steps and settling live and where the model's PSD is
    only extrapolated: a sensor's bias wander the model lacks (bias instability) must
    not pose as such an effect."""
    K = MIN_BAND_BINS
    if len(S) < 2 * K:
        return S
    P = np.abs(Rf[1:K]) ** 2 / n
    S0 = S[1:K]
    F = S[K] * K / np.arange(1, K)

    def nll(ln_b: float) -> float:
        s = S0 + math.exp(ln_b) * F
        return float(np.sum(P / s + np.log(s)))

    r = minimize_scalar(nll, bounds=(-20.0, 10.0), method="bounded")
    if 2.0 * (float(np.sum(P / S0 + np.log(S0))) - float(r.fun)) <= LOW_FLICKER_CHI2:
        return S
    out = S.copy()
    out[1:K] = S0 + math.exp(float(r.x)) * F
    return out


def weighted_products(w: np.ndarray, Xf: np.ndarray, Yf: np.ndarray,
                      lead: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A = Re(X^H diag(w) X) (p x p) and b = Re(X^H diag(w) Y) (p) of complex columns Xf
    (bins x p; ``lead``, when given, a column before them) and Yf (bins), as sums of real
    products in numpy's own loops (a threaded BLAS call on such thin products spends more
    time waking threads than multiplying, up to 40x on a loaded machine). The columns
    are read two at a time (memory: no stacked or transposed copy of a record-length
    design; each pair is copied again for the row after, which costs little beside the
    products)."""
    cols = ([] if lead is None else [lead]) + [Xf[:, j] for j in range(Xf.shape[1])]
    p = len(cols)
    yv = _real_pairs(Yf)
    A, b = np.empty((p, p)), np.empty(p)
    for i in range(p):
        ci = _real_pairs(cols[i])
        b[i] = np.einsum("k,kc,kc->", w, ci, yv)
        for j in range(i):
            A[i, j] = A[j, i] = np.einsum("k,kc,kc->", w, ci, _real_pairs(cols[j]))
        A[i, i] = np.einsum("k,kc,kc->", w, ci, ci)
    return A, b


def _real_pairs(z: np.ndarray) -> np.ndarray:
    """Complex column ``z`` as a contiguous (bins x 2) array of its real and imaginary parts."""
    return np.ascontiguousarray(z, dtype=np.complex128).view(np.float64).reshape(len(z), 2)


@dataclass(frozen=True)
class GlsFit:
    """Result of a Whittle GLS fit: coefficients ``beta``, covariance ``cov`` and the
    chi-square drop ``chi2_gain`` (likelihood-ratio statistic, p degrees of freedom)."""

    beta: np.ndarray
    cov: np.ndarray
    chi2_gain: float

    @property
    def se(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.cov), 0.0))


def _masked(x: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    """``x`` (n or n x p) as float64, 0 where not ``valid`` (and NaN as 0, numpy.nan_to_num)."""
    x = np.asarray(x, dtype=np.float64)
    if valid is not None:
        x = np.where(valid if x.ndim == 1 else valid[:, None], x, 0.0)
    return x if np.isfinite(x).all() else np.nan_to_num(x)


class Whittle:
    """Whittle GLS on an n-sample uniform record with noise PSD ``S`` at the rfft bins.

    ``valid`` marks usable samples: invalid ones are zeroed in the residual and in every
    design column, so they carry no information. With gaps, the fits hold the record's
    mean over the valid samples free (a nuisance column, the DFT of the valid mask,
    profiled out): a zero-filled gap is otherwise a jump from the residual's level to 0
    and back, which under a red (flicker) PSD weighs like data - a bias step added to a
    real RLG record cut into 35 stationary pieces by the motion gate was fitted at half
    its size, pulled towards the residual's mean level after it."""

    def __init__(self, S: np.ndarray, n: int, valid: np.ndarray | None = None):
        self.n = n
        self.S = S
        mult = np.full(len(S), 2.0)
        mult[0] = 0.0
        if n % 2 == 0:
            mult[-1] = 1.0
        self.w = mult / (n * S)
        #: how often each rfft bin counts in a sum over the full DFT (0 for the mean's bin 0)
        self.mult = mult
        self.valid = None if valid is None or valid.all() else valid
        #: the DFT of the valid mask: the mean's nuisance column when there are gaps
        self.ones = None if self.valid is None else np.fft.rfft(self.valid.astype(np.float64))
        #: values derived from S alone, computed once (detectors.kernel_length)
        self.memo: dict = {}

    def fft(self, x: np.ndarray) -> np.ndarray:
        """DFT (rfft) of one column or of the columns of a 2-D array (n x p; column by
        column: memory, one masked copy of a column at a time)."""
        if np.ndim(x) == 1:
            return np.fft.rfft(_masked(x, self.valid))
        out = np.empty((self.n // 2 + 1, x.shape[1]), dtype=np.complex128)
        for j in range(x.shape[1]):
            out[:, j] = np.fft.rfft(_masked(x[:, j], self.valid))
        return out

    def gls(self, Xf: np.ndarray, Yf: np.ndarray) -> GlsFit:
        """Fit Y = X beta (both already transformed by :meth:`fft`; Xf is bins x p)."""
        X = Xf.reshape(len(self.w), -1)
        if self.ones is None:
            A, b = weighted_products(self.w, X, Yf)
        else:  # the mean profiled out (class docstring): the Schur complement of its column
            A1, b1 = weighted_products(self.w, X, Yf, lead=self.ones)
            a00 = A1[0, 0] if A1[0, 0] > 0 else np.inf
            A = A1[1:, 1:] - np.outer(A1[1:, 0], A1[0, 1:]) / a00
            b = b1[1:] - A1[1:, 0] * b1[0] / a00
        try:
            cov = np.linalg.pinv(A, rcond=1e-12, hermitian=True)
        except np.linalg.LinAlgError:
            cov = np.full_like(A, np.nan)
        beta = cov @ b
        return GlsFit(beta, cov, float(b @ beta))

    def weights(self, Xf: np.ndarray, cov: np.ndarray) -> np.ndarray:
        """The estimator of :meth:`gls` (its covariance ``cov``, of Xf) as weights in time:
        a (p x n) with beta = a @ y for the residual y (0 where not valid; a is 0 there),
        the mean profiled out as in :meth:`gls`. sum_k w_k Re(conj(X_k) Y_k) is
        irfft(X_k / S_k) . y (w_k = mult_k / (n S_k), bin 0 unweighted)."""
        X = Xf.reshape(len(self.w), -1)
        inv_s = np.where(self.w > 0, 1.0 / self.S, 0.0)
        g = np.fft.irfft(X * inv_s[:, None], self.n, axis=0).T
        if self.ones is not None:
            A1, _ = weighted_products(self.w, X, np.zeros(len(self.w), dtype=np.complex128), lead=self.ones)
            if A1[0, 0] > 0:
                g = g - np.outer(A1[1:, 0] / A1[0, 0], np.fft.irfft(self.ones * inv_s, self.n))
        a = cov @ g
        if self.valid is not None:
            a[:, ~self.valid] = 0.0
        return a

    def circulant_covs(self, a: np.ndarray, *psds: np.ndarray) -> list[np.ndarray]:
        """Covariance (p x p) of the functionals a @ y (a: p x n) of noise of each PSD in
        ``psds`` (at the rfft bins) as the Whittle likelihood takes it (the record circular,
        bins independent; bin 0, the mean, and bins where S is not finite, outside a
        filter's pass band, left out): sum_k mult_k S_k A_k conj(A_k)' / n."""
        Af = np.fft.rfft(a, axis=1)
        return [((Af * (self.mult * np.where((self.mult > 0) & np.isfinite(S), S, 0.0))) @ Af.conj().T).real / self.n
                for S in psds]

    def chi2(self, Rf: np.ndarray) -> float:
        """Whittle chi-square of a transformed residual."""
        return float(np.sum(self.w * np.abs(Rf) ** 2))

    def chi2_left(self, Rf: np.ndarray, Nf: np.ndarray | None = None) -> float:
        """Whittle chi-square of a transformed residual once the nuisance columns ``Nf``
        (bins x q, transformed; none by default) and, with gaps, the mean over the valid
        samples are fitted out of it."""
        X = Nf.reshape(len(Rf), -1) if Nf is not None and Nf.size else np.zeros((len(Rf), 0), dtype=np.complex128)
        if self.ones is None and not X.shape[1]:
            return self.chi2(Rf)
        A, b = weighted_products(self.w, X, Rf, lead=self.ones)
        return self.chi2(Rf) - float(b @ np.linalg.pinv(A, rcond=1e-12, hermitian=True) @ b)


#: a scan of a slow effect's nonlinear parameter runs on about this many block means of the
#: record (``Coarse``): drifts, steps and settling lose nothing of their power
COARSE_BLOCKS = 1 << 16


class Coarse:
    """The exact Whittle GLS of the block means of a record (blocks of ``b`` samples, the
    first n' b samples of the record, n' = n // b): for scans of slow effects, each
    design costs an FFT of n' samples instead of n. The block means' PSD is the
    calibrated PSD ``S`` (rfft bins of the n-sample record) aliased through the block
    average: at bin k' of the n' block means, sin^2(pi k' / n') / b^3 sum over l of
    S(k' + l n') / sin^2(pi (k' + l n') / N) (N = n' b; S read at the nearest bin of
    the n-sample record; no power where S is infinite, outside the model's pass band).
    Invalid samples count as 0 in every block mean, as in the full GLS. A design is given
    at the blocks' centre times ``t`` (s; its block mean for a design that varies slowly
    over a block) and weighted by each block's valid share."""

    def __init__(self, S: np.ndarray, y: np.ndarray, valid: np.ndarray | None, t_s: np.ndarray, b: int):
        n = len(y)
        self.b = b
        nb = self.nb = n // b
        N = nb * b
        k = np.arange(N)
        src = np.minimum(np.rint(np.minimum(k, N - k) * n / N).astype(np.int64), len(S) - 1)
        Sf = np.where(np.isfinite(S), S, 0.0)[src]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(k > 0, Sf / np.sin(np.pi * k / N) ** 2, 0.0)
        folded = ratio.reshape(b, nb).sum(axis=0)[: nb // 2 + 1]
        kp = np.arange(nb // 2 + 1)
        Sb = np.sin(np.pi * kp / nb) ** 2 / b ** 3 * folded
        Sb[0] = np.inf
        self.wh = Whittle(np.where(Sb > 0, Sb, np.inf), nb)
        self.t = t_s[:N].reshape(nb, b).mean(axis=1)
        self.share = None if valid is None else valid[:N].reshape(nb, b).mean(axis=1)
        self.Yf = np.fft.rfft(_masked(y, valid)[:N].reshape(nb, b).mean(axis=1))

    def gain(self, Xb: np.ndarray) -> float:
        """GLS chi-square gain of the design ``Xb`` (n' or n' x p) at the blocks' centre times."""
        Xb = np.asarray(Xb, dtype=np.float64)
        if self.share is not None:
            Xb = Xb * (self.share if Xb.ndim == 1 else self.share[:, None])
        return self.wh.gls(np.fft.rfft(Xb, axis=0), self.Yf).chi2_gain


def coarse_block(n: int) -> int:
    """Block length (samples) of the scans on block means of an n-sample record: 1 (no
    blocks) up to 2 COARSE_BLOCKS samples, else n // COARSE_BLOCKS."""
    return 1 if n < 2 * COARSE_BLOCKS else n // COARSE_BLOCKS


def model_psd(model, omega: np.ndarray, n: int, white_dpsh: float | None = None) -> np.ndarray:
    """Noise PSD (see :func:`noise_psd`) of a SensorModel's stochastic part at ``omega``
    for an n-sample record: IEEE-952 terms (flicker as the simulator's exact sum of
    Gauss-Markov terms), ``markov``, ``lowpass_noise`` and ``vibration_lines`` effects and ``bandwidth``
    filters. ``white_dpsh``
    overrides N (deg/sqrt(h)), e.g. with the RMS level of white-level effects."""
    from fogmon.sim.noise import default_flicker_tau_hi_s, flicker_taus, lowpass_psd

    sample_rate_hz = float(model.sample_rate_hz)
    nz = model.noise
    markov = [(e.params["sigma_dph"], e.params["tau_c_s"]) for e in model.effects if e.kind == "markov"]
    if nz.B_dph > 0:
        sig = nz.B_dph * math.sqrt(math.log(2.0) / math.pi)
        markov += [
            (sig, tc)
            for tc in flicker_taus(sample_rate_hz, default_flicker_tau_hi_s(sample_rate_hz, n / sample_rate_hz))
        ]
    S = noise_psd(omega, sample_rate_hz, nz.Q_arcsec, nz.N_dpsh if white_dpsh is None else white_dpsh, nz.K_dphsh,
                  tuple(markov))
    for e in model.effects:
        if e.kind == "vibration_lines":
            S = S + lines_psd(e.params, sample_rate_hz, omega)
        if e.kind == "lowpass_noise":
            p = e.params
            S = S + lowpass_psd(omega, p["sigma_dph"], p["cutoff_hz"], p["order"], sample_rate_hz)
    for e in model.effects:
        if e.kind == "bandwidth":
            S = S * filter_gain2(e.params, sample_rate_hz, omega)
    return S


def lines_psd(params: dict, sample_rate_hz: float, omega: np.ndarray) -> np.ndarray:
    """PSD (see :func:`noise_psd`) of a ``vibration_lines`` effect: the sum of its lines."""
    from fogmon.sim.noise import line_psd

    S = np.zeros(len(omega))
    for f, sig, bw in zip(params["freq_hz"], params["sigma_dph"], params["bandwidth_hz"], strict=True):
        S += line_psd(omega, sample_rate_hz, f, sig, bw)
    return S


def filter_gain2(params: dict, sample_rate_hz: float, omega: np.ndarray) -> np.ndarray:
    """|H|^2 of a ``bandwidth`` effect (Butterworth or FIR) at ``omega`` (rad/sample). The
    Butterworth is scipy's digital design (``sim.noise.lowpass_filter``: the analogue
    prototype through the prewarped bilinear transform), so exactly
    1 / (1 + (tan(omega / 2) / tan(pi fc / fs))^(2 order)) - closed form, no polynomial
    evaluation (the same values to 1e-12 of the pass-band gain)."""
    if params.get("taps"):
        _, h = signal.freqz(params["taps"], [1.0], worN=omega)
        return np.abs(h) ** 2
    with np.errstate(over="ignore"):
        x = np.tan(np.asarray(omega, dtype=np.float64) / 2.0) / math.tan(math.pi * params["cutoff_hz"] / sample_rate_hz)
        return 1.0 / (1.0 + x ** (2 * int(params["order"])))


def avar1_of_psd(S: np.ndarray, n: int) -> float:
    """Allan variance at tau = tau0 implied by a PSD at the rfft bins:
    2 * integral S(nu) sin^2(pi nu) dnu over the circle."""
    w = rfft_omega(n)
    mult = np.full(len(S), 2.0)
    mult[0] = 0.0
    if n % 2 == 0:
        mult[-1] = 1.0
    Sf = np.where(np.isfinite(S), S, 0.0)
    return float(2.0 * np.sum(mult * Sf * np.sin(w / 2.0) ** 2) / n)


class BinnedPeriodogram:
    """Periodogram I_k = |Y_k|^2 / n averaged in frequency bins (the union of ``n_bins``
    log-spaced and ``n_linear`` equal-width bins: low bins kept single, none wider than
    1/n_linear of the band, so a filter's fall-off near Nyquist is resolved), for fast
    Whittle likelihoods of PSD models."""

    def __init__(self, Yf: np.ndarray, n: int, n_bins: int = 1500, n_linear: int = 20000):
        k = np.arange(len(Yf))
        mult = np.full(len(Yf), 2.0)
        mult[0] = 0.0
        if n % 2 == 0:
            mult[-1] = 1.0
        edges = np.unique(np.concatenate((np.round(np.geomspace(1, len(Yf), n_bins)),
                                          np.round(np.linspace(1, len(Yf), n_linear)))).astype(np.int64))
        edges = np.concatenate((edges[edges < len(Yf)], [len(Yf)]))
        pgram = np.abs(Yf) ** 2 / n
        cw = np.concatenate(([0.0], np.cumsum(mult)))
        ci = np.concatenate(([0.0], np.cumsum(mult * pgram)))
        ck = np.concatenate(([0.0], np.cumsum(mult * k)))
        lo, hi = edges[:-1], edges[1:]
        self.count = cw[hi] - cw[lo]
        keep = self.count > 0
        self.count = self.count[keep]
        self.I = (ci[hi] - ci[lo])[keep] / self.count
        self.k = (ck[hi] - ck[lo])[keep] / self.count
        self.n = n
        self.omega = 2.0 * np.pi * self.k / n

    def deviance(self, S: np.ndarray, floor: float = 0.0, keep: np.ndarray | None = None) -> float:
        """-2 ln(Whittle likelihood) (up to a constant) of PSD values S at the bins (only
        the ``keep`` ones, when given), S floored at ``floor`` (a finite record's
        periodogram cannot follow a filter's zero: leakage from the rest of the band fills it)."""
        terms = self._terms(S, floor)
        return float(np.sum(terms if keep is None else terms[keep]))

    def deviances(self, S: np.ndarray, floor: float = 0.0) -> np.ndarray:
        """:meth:`deviance` of each row of ``S`` (models x bins), over all bins."""
        return self._terms(S, floor).sum(axis=1)

    def _terms(self, S: np.ndarray, floor: float) -> np.ndarray:
        S = np.maximum(S, max(floor, 1e-300))
        return self.count * (np.log(S) + self.I / S)
