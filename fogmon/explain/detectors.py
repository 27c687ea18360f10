"""Matched time-domain tests run beside the mismatch map (docs/explain.md): isolated spikes
and a single bias step, both as Whittle GLS scans over every sample position, so
they are optimal for the model's noise colour (a spike far below the raw-sample
noise is found when that noise is quantization, i.e. blue); and, for what is left
unexplained, narrowband lines and band-limited rms bursts.

The scans cost a few FFTs of the record whatever its length.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, special, stats

from fogmon.explain.fitting import Whittle


def bonferroni_z(n_tests: int, alpha: float = 0.01) -> float:
    """Two-sided normal threshold with family-wise error ``alpha`` over ``n_tests``."""
    return float(stats.norm.isf(alpha / (2.0 * max(n_tests, 1))))


def expected_max_abs_z(n_tests: int) -> float:
    """Median of the largest |z| of ``n_tests`` independent standard normals."""
    return float(stats.norm.isf((1.0 - 0.5 ** (1.0 / max(n_tests, 1))) / 2.0))


def spike_scan(wh: Whittle, Yf: np.ndarray, block: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """GLS amplitude (residual units) and z-statistic of a one-sample spike at every
    sample position (length n each); z is scaled by a local robust scale (MAD in blocks
    of 4096 samples) so that a mis-stated or time-varying noise level (vibration,
    temperature) does not create spikes. ``block`` should be many matched-filter
    lengths (the z of neighbouring samples correlate over that length). z is 0 within
    3 matched-filter lengths of either end, where the circular filter joins the
    record's ends (an angle jump there looks like a spike in blue noise)."""
    Z = Yf / wh.S
    Z[0] = 0.0
    b = np.fft.irfft(Z, wh.n)
    A = float(np.sum(wh.w))
    z = b / np.sqrt(A)
    if wh.valid is not None:
        z = np.where(wh.valid, z, 0.0)
    z = z / local_scale(z, wh.valid, block)
    edge = min(3 * kernel_length(wh), wh.n // 10)
    z[:edge] = 0.0   # the circular filter joins the record's ends: no test there
    z[wh.n - edge:] = 0.0
    return b / A, z


def local_scale(z: np.ndarray, valid: np.ndarray | None, block: int = 4096) -> np.ndarray:
    """Robust standard deviation (1.4826 MAD) of z in consecutive blocks, per sample."""
    n = len(z)
    nb = max(1, n // block)
    edges = np.linspace(0, n, nb + 1).astype(np.int64)
    out = np.empty(n)
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        seg = z[lo:hi] if valid is None else z[lo:hi][valid[lo:hi]]
        mad = 1.4826 * float(np.median(np.abs(seg - np.median(seg)))) if len(seg) > 16 else 0.0
        out[lo:hi] = mad
    good = out > 0
    if not good.any():
        return np.ones(n)
    out[~good] = np.median(out[good])
    return out


def find_spikes(z: np.ndarray, threshold: float, min_sep: int = 1) -> np.ndarray:
    """Sample indices of spikes: local maxima of |z| above ``threshold``, strongest first,
    each suppressing the samples closer than ``min_sep`` to it (a spike lights up its
    neighbours when the noise is blue: ``min_sep`` is the matched filter's half-width,
    :func:`kernel_length`, the first lag its response falls below 1/e, so the sample at
    ``min_sep`` is not lit up - and in white noise, ``min_sep`` 1, each sample beyond the
    threshold is its own spike: two adjacent outliers are two spikes, not one);
    every one found (no cap), sorted by index."""
    a = np.abs(z)
    cand = np.flatnonzero(a > threshold)
    if not len(cand):
        return np.zeros(0, dtype=np.int64)
    cand = cand[np.argsort(-a[cand], kind="stable")]
    taken = np.zeros(len(z), dtype=bool)  # within min_sep of a chosen spike
    chosen = []
    for i in cand.tolist():
        if not taken[i]:
            chosen.append(i)
            taken[max(i - min_sep + 1, 0): i + min_sep] = True
    return np.array(sorted(chosen), dtype=np.int64)


#: the step-down search stops after this many rescalings (each a local-scale pass, no FFT)
STEP_DOWN_PASSES = 32


def find_spikes_step_down(z: np.ndarray, threshold: float, min_sep: int = 1,
                          block: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """Spikes beyond ``threshold`` against the robust scale of the noise *without* them:
    :func:`find_spikes` on ``z`` (a spike scan's statistic, 0 where untested), then ``z``
    rescaled by the local robust scale (:func:`local_scale`, the same ``block``) of the
    tested samples a spike found does not light up (those under ``min_sep`` from it: the
    matched filter's half-width, :func:`kernel_length`), and the search repeated until
    it finds no new spike (at most STEP_DOWN_PASSES rescalings). The MAD of noise holding
    a fraction f of spikes is inflated by about f (heavy-tailed noise: more), which hides
    the spikes just beyond the threshold; the MAD of Gaussian noise cut at the threshold
    is that of the whole noise (within 1e-6 at |z| 5), so a spike-free block keeps its scale.
    A step-down: with nothing beyond the threshold at first, nothing changes (the
    family-wise level under pure noise is the single test's). Returns (z rescaled, the
    spikes' indices sorted)."""
    idx = find_spikes(z, threshold, min_sep)
    if not len(idx):
        return z, idx
    n = len(z)
    tested = z != 0.0
    found = np.zeros(n, dtype=bool)
    out = z
    for _ in range(STEP_DOWN_PASSES):
        near = _within(idx, min_sep - 1, n)
        if not (near & ~found).any():
            break
        found |= near
        out = z / local_scale(z, tested & ~found, block)
        idx = find_spikes(out, threshold, min_sep)
    return out, idx


def _within(idx: np.ndarray, sep: int, n: int) -> np.ndarray:
    """Mask of the samples within ``sep`` of any index in ``idx``."""
    d = np.zeros(n + 1, dtype=np.int64)
    np.add.at(d, np.maximum(idx - sep, 0), 1)
    np.add.at(d, np.minimum(idx + sep + 1, n), -1)
    return np.cumsum(d[:n]) > 0


@dataclass(frozen=True)
class Contamination:
    """Contaminated-Gaussian law of a standardised statistic z: (1 - eps) N(0, 1) +
    eps N(0, s^2), fitted by maximum likelihood; ``gain`` = 2 x (log-likelihood minus
    that of N(0, 1)), a chi-square-type statistic with 2 parameters."""

    eps: float
    s: float
    gain: float

    def log_odds(self, z: np.ndarray) -> np.ndarray:
        """ln P(contaminated | z) / P(clean | z)."""
        return (math.log(self.eps / (1.0 - self.eps)) - math.log(self.s)
                + 0.5 * np.square(z) * (1.0 - 1.0 / self.s ** 2))

    def loglik_gain(self, z: np.ndarray) -> float:
        """2 x sum of ln f(z) / phi(z) over ``z`` (the chi-square gain on other data)."""
        return 2.0 * float(np.sum(np.logaddexp(math.log1p(-self.eps), math.log(self.eps) - math.log(self.s)
                                               + 0.5 * np.square(z) * (1.0 - 1.0 / self.s ** 2))))

    @property
    def z_even(self) -> float:
        """|z| where a sample is as likely contaminated as clean (posterior 1/2)."""
        return math.sqrt(2.0 * math.log((1.0 - self.eps) * self.s / self.eps) / (1.0 - 1.0 / self.s ** 2))

    def bonferroni_z(self, n_tests: int, alpha: float = 0.01) -> float:
        """Two-sided |z| threshold with family-wise error ``alpha`` over ``n_tests`` when
        z follows this law: (1 - eps) P(|Z| > t) + eps P(|Z| > t / s) = alpha / n_tests."""
        target = alpha / max(n_tests, 1)
        def excess(t: float) -> float:
            return 2.0 * ((1.0 - self.eps) * stats.norm.sf(t) + self.eps * stats.norm.sf(t / self.s)) - target
        lo = bonferroni_z(n_tests, alpha)
        hi = max(self.s, 1.0) * (lo + 2.0)
        return float(optimize.brentq(excess, lo, hi)) if excess(lo) > 0 else lo


def fit_contamination(z: np.ndarray, iterations: int = 100) -> Contamination | None:
    """EM fit of :class:`Contamination` to ``z`` (clean part N(0, 1)); None when fewer
    than 3 samples lie beyond |z| = 4 (nothing to fit a tail to)."""
    z2 = np.square(np.asarray(z, dtype=float))
    n = len(z2)
    far = z2 > 16.0
    if n < 100 or far.sum() < 3:
        return None
    # EM on z^2 binned by |z| in steps of 0.01 (the posterior barely changes within a
    # bin): the iterations cost O(bins), not O(n)
    key = np.minimum((np.sqrt(z2) * 100.0).astype(np.int64), 100_000)
    cnt = np.bincount(key)
    used = cnt > 0
    zb = np.bincount(key, weights=z2)[used] / cnt[used]
    cnt = cnt[used].astype(float)
    eps, s2 = far.mean(), max(float(z2[far].mean()), 20.0)
    for _ in range(iterations):
        lo = math.log(eps / (1.0 - eps)) - 0.5 * math.log(s2) + 0.5 * zb * (1.0 - 1.0 / s2)
        w = cnt * special.expit(lo)
        sw = float(w.sum())
        eps_new = min(max(sw / n, 1.0 / n), 0.5)
        s2_new = max(float(w @ zb) / max(sw, 1e-300), 1.5)
        done = abs(eps_new - eps) <= 1e-4 * eps and abs(s2_new - s2) <= 1e-4 * s2
        eps, s2 = eps_new, s2_new
        if done:
            break
    c = Contamination(eps, math.sqrt(s2), 0.0)
    return Contamination(eps, c.s, c.loglik_gain(z))


def kernel_length(wh: Whittle) -> int:
    """Half-width (samples) of the GLS matched filter's response to one spike: where the
    inverse-PSD autocorrelation falls below 1/e of its peak (1 for white noise);
    computed once per ``wh``."""
    if "kernel_length" not in wh.memo:
        Z = 1.0 / wh.S
        Z[0] = 0.0
        r = np.fft.irfft(Z, wh.n)
        r = r / r[0]
        below = np.flatnonzero(np.abs(r[: wh.n // 2]) < math.exp(-1.0))
        wh.memo["kernel_length"] = int(max(1, below[0])) if len(below) else wh.n // 4
    return wh.memo["kernel_length"]


def spike_at_start(wh: Whittle, Yf: np.ndarray) -> float:
    """The GLS amplitude of a one-sample spike at sample 0 (``spike_scan``'s amplitude
    there, without its inverse FFT: the inverse DFT's first value is the plain sum)."""
    Z = Yf / wh.S
    n = wh.n
    inner = Z[1: n // 2] if n % 2 == 0 else Z[1:]
    b = 2.0 * float(np.sum(inner.real)) + (float(Z[-1].real) if n % 2 == 0 else 0.0)
    return b / n / float(np.sum(wh.w))


#: the step scan's spectra and gains are formed this many bins (samples) at a time (memory:
#: no record-length temporaries beside the two transforms)
STEP_CHUNK = 1 << 20


def step_scan(wh: Whittle, Yf: np.ndarray, lo: int, hi: int) -> tuple[int, float, float]:
    """Best single bias step (column 1 for samples >= n0) with n0 in [lo, hi).

    Returns (n0, step estimate in the residual's units, chi-square gain). With d_k =
    1 - e^(2 pi i k / n) and C_k = 1 / (S_k |d_k|^2), the GLS products of the step at
    every n0 are b = irfft(Y / (S d)) - its value at 0 and A = 2 (c_0 - c), c =
    irfft(C); the gain is b^2 / A. The spectra are formed a chunk of STEP_CHUNK bins
    at a time and the gains of a chunk of positions at a time, each straight into the
    transform's input (C as a complex array: a real one would be copied to complex):
    at a 1e7-sample record, two record-length arrays beside the transforms' input and
    output instead of five."""
    n, nb = wh.n, len(Yf)
    spec = np.empty(nb, dtype=np.complex128)
    for k, d, S in _step_chunks(wh, nb):
        z = Yf[k] / S  # S may be inf (no weight): real division first, no inf / inf
        z /= d
        spec[k] = z
    spec[0] = 0.0
    b = np.fft.irfft(spec, n)
    b -= b[0]
    for k, d, S in _step_chunks(wh, nb):
        m = d.real ** 2 + d.imag ** 2
        m *= S
        np.divide(1.0, m, out=m)  # C = 1 / (S |d|^2)
        spec[k] = m
    spec[0] = 0.0
    A = np.fft.irfft(spec, n)
    del spec
    A -= A[0]
    A *= -2.0  # A = 2 (cq[0] - cq)
    start = max(lo, 1)
    stop = max(min(hi, n), start + 1)
    best, n0 = -1.0, start
    for a in range(start, stop, STEP_CHUNK):
        sl = slice(a, min(a + STEP_CHUNK, stop))
        pos = A[sl] > 0
        gain = np.square(b[sl])   # b^2 / A where A > 0
        np.divide(gain, A[sl], out=gain, where=pos)
        gain[~pos] = 0.0
        k = int(np.argmax(gain))
        if gain[k] > best:
            best, n0 = float(gain[k]), a + k
    return n0, float(b[n0] / A[n0]), best


def _step_chunks(wh: Whittle, nb: int):
    """(bins, d, S) of the step scan's spectra, STEP_CHUNK bins at a time: d_k =
    1 - e^(2 pi i k / n) and the PSD S_k, both 1 at bin 0 (left out)."""
    for a in range(0, nb, STEP_CHUNK):
        k = slice(a, min(a + STEP_CHUNK, nb))
        d = 1.0 - np.exp((2j * np.pi / wh.n) * np.arange(k.start, k.stop))
        S = wh.S[k].copy()
        if a == 0:
            d[0], S[0] = 1.0, 1.0
        yield k, d, S


#: samples' worth of Welch segments transformed at once by ``spectral_lines`` (memory: ~5
#: copies of them, 8 bytes each)
_WELCH_RUN = 2**20


def spectral_lines(y: np.ndarray, sample_rate_hz: float, f_lo_hz: float, f_hi_hz: float,
                   min_ratio: float = 10.0) -> list[tuple[float, float]]:
    """Narrowband lines in ``y`` (deg/h) between f_lo_hz and f_hi_hz: local maxima of the
    Welch PSD standing ``min_ratio`` times above the median PSD of that band (a
    broadband noise shape has no such peak). Returns every such line, one per 10 % of
    frequency, as (frequency Hz, peak / band median) pairs, strongest first. Invalid samples (NaN) are set to the
    mean: this is a hint for the report, not a fit."""
    from scipy.signal import find_peaks, welch

    x = np.asarray(y, dtype=float)
    ok = np.isfinite(x)
    if ok.sum() < 256:
        return []
    mean = x[ok].mean()
    x = np.where(ok, x, mean)
    x -= mean   # (one record-length copy, not two)
    nperseg = min(len(x), max(256, int(2 ** math.ceil(math.log2(8 * sample_rate_hz / max(f_lo_hz, 1e-9))))))
    # Welch's mean over all segments, taken over runs of them (welch copies its segments
    # several times: ~5 x the record at once in one call)
    step = nperseg - nperseg // 2   # welch's default overlap: half a segment
    n_seg = (len(x) - nperseg) // step + 1
    per_run = max(1, _WELCH_RUN // nperseg)
    p = np.zeros(nperseg // 2 + 1)
    for s0 in range(0, n_seg, per_run):
        k = min(per_run, n_seg - s0)
        f, pk = welch(x[s0 * step: (s0 + k - 1) * step + nperseg], fs=sample_rate_hz, nperseg=nperseg)
        p += pk * (k / n_seg)   # (one run: the welch of the whole record, unchanged)
    band = (f >= f_lo_hz) & (f <= min(f_hi_hz, sample_rate_hz / 2)) & (f > 0)
    if band.sum() < 8:
        return []
    fb, pb = f[band], p[band]
    med = float(np.median(pb))
    if med <= 0:
        return []
    peaks, _ = find_peaks(pb, height=min_ratio * med)
    best: list[int] = []
    for i in sorted(peaks, key=lambda i: -pb[i]):  # one line per 10 % of frequency
        if all(abs(fb[i] - fb[j]) > 0.1 * fb[j] for j in best):
            best.append(i)
    return [(float(fb[i]), float(pb[i] / med)) for i in best]


def tau_band_hz(tau_min_s: float, tau_max_s: float, sample_rate_hz: float) -> tuple[float, float]:
    """(low, high) frequency (Hz) an Allan deviation at taus tau_min_s..tau_max_s responds
    to: a sinusoid of frequency f peaks at tau = 0.371 / f; the band reaches an octave
    beyond the peaks of tau_max_s and tau_min_s on either side, up to the Nyquist frequency."""
    return 0.371 / (2.0 * tau_max_s), min(sample_rate_hz / 2.0, 0.371 / (0.5 * tau_min_s))


@dataclass(frozen=True)
class Burst:
    """Band-limited rms of a span against the record's other spans of its length:
    ``rms_ratio`` (span / median of the others), ``z`` = ln(rms_ratio) / sd, ``sd`` the
    larger of the chance scatter of a Gaussian noise's log rms in that band and span
    and the others' robust scatter, over ``spans_n`` other spans."""

    f_lo_hz: float
    f_hi_hz: float
    rms_ratio: float
    z: float
    sd: float
    spans_n: int


#: a burst test needs this many other spans of the same length in the record
BURST_MIN_SPANS = 4


def band_rms_burst(y: np.ndarray, valid: np.ndarray, sample_rate_hz: float, i0: int, i1: int,
                   f_lo_hz: float, f_hi_hz: float) -> Burst | None:
    """Rms of ``y`` (deg/h, 0 where not ``valid``) through a zero-phase 4-pole Butterworth
    band-pass f_lo_hz..f_hi_hz (a high-pass when f_hi_hz is the Nyquist frequency) over
    samples i0..i1, against the median rms of the record's non-overlapping spans of the
    same length that do not touch it (:class:`Burst`). The chance scatter of a log rms
    is 1 / (2 sqrt(W D)) for a band W Hz wide over D s (2 W D degrees of freedom).
    None when fewer than BURST_MIN_SPANS such spans exist."""
    from scipy.signal import butter, sosfiltfilt

    n = len(y)
    L = max(i1 - i0, 16)
    nyq = sample_rate_hz / 2.0
    lo = max(f_lo_hz, 1.0 / (n / sample_rate_hz))
    if f_hi_hz >= 0.95 * nyq:
        sos = butter(4, lo, btype="highpass", fs=sample_rate_hz, output="sos")
        width = nyq - lo
    else:
        sos = butter(4, [lo, f_hi_hz], btype="bandpass", fs=sample_rate_hz, output="sos")
        width = f_hi_hz - lo
    x = sosfiltfilt(sos, np.where(valid, y, 0.0))

    def rms(a: int, b: int) -> float:
        v = valid[a:b]
        return math.sqrt(float(np.mean(x[a:b][v] ** 2))) if v.sum() > L // 2 else float("nan")

    others = np.array([rms(a, a + L) for a in range(0, n - L + 1, L) if a + L <= i0 or a >= i1])
    others = others[np.isfinite(others) & (others > 0)]
    here = rms(i0, i1)
    if len(others) < BURST_MIN_SPANS or not here > 0:
        return None
    med = float(np.median(others))
    ln_o = np.log(others)
    sd = max(0.5 / math.sqrt(width * L / sample_rate_hz), 1.4826 * float(np.median(np.abs(ln_o - np.median(ln_o)))))
    return Burst(lo, f_hi_hz, here / med, math.log(here / med) / sd, sd, len(others))
