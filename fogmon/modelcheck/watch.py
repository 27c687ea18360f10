"""The live model check (docs/modelcheck.md): one call per DADEV window, a ``model_band``
event when the gyro leaves its model's band (where, how much, which tau shape, which aux
channel co-varies) and one when it is back, and a session summary.

A departure starts at the first window out of the band (|z| > threshold at any tau). It
ends once a whole window of data after the last window out is in band (the windows
ending at least ``window_s`` after it, and every one in between, are in band): one
excursion makes one departure however many overlapping windows it touches, so a
departure is not re-raised each hop while the band edge is crossed back and forth.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from fogmon.block import Event
from fogmon.modelcheck.band import ModelBand

#: A departure's aux statistic co-varies when it lies this many standard deviations (of
#: that statistic over the in-band windows) from its in-band mean.
COVARY_Z = 4.0
#: In-band windows needed before aux channels are compared.
MIN_BASELINE_WINDOWS = 3
#: What each known aux channel is, and its unit.
AUX_MEANING = {"vib_g": ("vibration", "g"), "temp_c": ("temperature", "degC"),
               "rot_dps": ("rotation", "deg/s"), "depth_m": ("depth", "m")}
STATS = ("mean", "std", "slope")

KIND = "model_band"


#: Aux samples per window the statistics are computed from (evenly spaced): the work per
#: window is bounded whatever its length; aux channels (temperature, vibration level,
#: turntable rate) change slowly against the sample rate.
AUX_POINTS = 1024


def aux_stats(x: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """(mean, standard deviation, least-squares slope per s) of one aux channel over a
    window of samples at ``sample_rate_hz`` (Hz), from at most AUX_POINTS evenly spaced samples
    (NaN samples ignored; NaN where fewer than two are finite)."""
    x = np.asarray(x, dtype=float)
    step = max(1, len(x) // AUX_POINTS)
    v = x[::step]
    ok = np.isfinite(v)
    if ok.sum() < 2:
        return np.full(3, np.nan)
    t = np.flatnonzero(ok) * (step / sample_rate_hz)
    v = v[ok]
    tc = t - t.mean()
    mean = float(v.mean())
    return np.array([mean, float(v.std()), float(np.dot(tc, v - mean) / np.dot(tc, tc))])


def tau_shape(z: np.ndarray, threshold: float) -> str:
    """Shape of a window's departure over taus (shortest first), from the tau of its
    largest |z| among the judged taus: below the band when that is a deficit; else a
    white-level rise when it lies in the shortest third of the taus or the shortest tau
    is out, a drift when it lies in the longest third and the longest tau is out, a hump
    otherwise (excess in a middle band)."""
    ok = np.flatnonzero(~np.isnan(z))
    zz = z[ok]
    k = int(np.argmax(np.abs(zz)))
    if zz[k] < 0:
        return "below the band (quieter than the model)"
    third = len(ok) / 3.0
    if k < third or zz[0] > threshold:
        return "white-level rise (excess at the shortest taus)"
    if k >= len(ok) - third and zz[-1] > threshold:
        return "drift (excess rising to the longest taus)"
    return "hump (excess in a middle tau band)"


class AuxWindows:
    """The aux samples of the windows the DADEV engine completes: push each block's aux
    channels (the same samples, in order, as the engine gets), then :meth:`window` gives
    the ``window_n`` samples ending at an absolute sample index the engine reported
    (``end_index``), for :meth:`ModelWatch.frame`. Holds at most one window plus the
    latest block per channel."""

    def __init__(self, names: Sequence[str], window_n: int) -> None:
        self.names = tuple(names)
        self.window_n = int(window_n)
        self._buf = {name: np.zeros(0) for name in self.names}
        self._base = 0  # absolute index of the buffers' first sample
        self._len = 0  # samples held

    def push(self, aux: dict[str, np.ndarray], n: int) -> None:
        """Append a block of ``n`` samples (a channel missing from ``aux``: NaN)."""
        drop = max(self._len - self.window_n, 0)
        for name in self.names:
            new = np.asarray(aux[name], dtype=float) if name in aux else np.full(n, np.nan)
            self._buf[name] = np.concatenate((self._buf[name][drop:], new))
        self._base += drop
        self._len += n - drop

    def window(self, end_index: int) -> dict[str, np.ndarray]:
        """name -> the aux samples of the window ending at sample ``end_index`` (absolute,
        from the first push); only the part still held (all of it for a window the last
        push completed)."""
        lo = max(int(end_index) - self.window_n + 1 - self._base, 0)
        hi = int(end_index) + 1 - self._base
        return {name: b[lo:hi] for name, b in self._buf.items()}


@dataclass
class _Baseline:
    """Running mean and variance (Welford) of the aux statistics of in-band windows."""

    n: dict = field(default_factory=dict)
    mean: dict = field(default_factory=dict)
    m2: dict = field(default_factory=dict)

    def add(self, name: str, s: np.ndarray) -> None:
        if not np.all(np.isfinite(s)):
            return
        n = self.n.get(name, 0) + 1
        mu = self.mean.get(name, np.zeros(3))
        d = s - mu
        mu = mu + d / n
        self.m2[name] = self.m2.get(name, np.zeros(3)) + d * (s - mu)
        self.n[name], self.mean[name] = n, mu

    def score(self, name: str, s: np.ndarray) -> np.ndarray | None:
        """|s - in-band mean| / in-band sd per statistic (the sd floored at 1e-9 of the
        mean's size, so a constant channel that moves at all scores high); None with
        too few in-band windows."""
        n = self.n.get(name, 0)
        if n < MIN_BASELINE_WINDOWS or not np.all(np.isfinite(s)):
            return None
        mu = self.mean[name]
        sd = np.sqrt(self.m2[name] / (n - 1))
        return np.abs(s - mu) / np.maximum(sd, 1e-9 * np.maximum(np.abs(mu), 1.0))


@dataclass
class _Departure:
    start_s: float            # start of the new data of the first window out (s)
    first_end_s: float        # end of the first window out (the alarm time)
    last_end_s: float         # end of the last window out so far
    tau_lo_s: float
    tau_hi_s: float
    peak_z: float
    peak_ratio: float
    peak_tau_s: float
    shape: str
    cause: str
    windows_out: int = 1
    end_s: float | None = None

    def as_dict(self) -> dict:
        return {"start_s": self.start_s, "end_s": self.end_s, "alarm_s": self.first_end_s,
                "last_out_s": self.last_end_s, "duration_s": self.last_end_s - self.start_s,
                "tau_min_s": self.tau_lo_s, "tau_max_s": self.tau_hi_s, "peak_ratio": self.peak_ratio,
                "peak_tau_s": self.peak_tau_s, "peak_abs_z": self.peak_z, "shape": self.shape,
                "cause": self.cause, "windows_out": self.windows_out, "open": self.end_s is None}


class ModelWatch:
    """Stateful live check against a :class:`ModelBand`: one :meth:`frame` call per DADEV
    window (in time order); ``aux_names`` are the aux channels whose window statistics
    (mean, std, slope per s) are compared to name the likely cause."""

    def __init__(self, band: ModelBand, aux_names: Sequence[str]) -> None:
        self.band = band
        self.aux_names = tuple(aux_names)
        self._base = _Baseline()
        self._dep: _Departure | None = None
        self._done: list[_Departure] = []
        self._last_end: float | None = None
        self.time_inside_s = 0.0
        self.time_outside_s = 0.0
        self.time_unjudged_s = 0.0
        self.windows = 0
        self.windows_out = 0
        self.windows_unjudged = 0

    def frame(self, t_end_s: float, adev_dph: np.ndarray, aux_window: dict[str, np.ndarray]) -> list[Event]:
        """Judge the window ending at ``t_end_s`` (s) with ADEV ``adev_dph`` (deg/h, the
        band's taus) and aux samples ``aux_window`` (name -> that window's samples).
        Returns the ``model_band`` events (at most one)."""
        band = self.band
        new_s = band.window_s if self._last_end is None else max(t_end_s - self._last_end, 0.0)
        self._last_end = t_end_s
        self.windows += 1
        z = band.z(adev_dph)
        judged = np.isfinite(z) | (z == np.inf)
        if not judged.any():
            self.time_unjudged_s += new_s
            self.windows_unjudged += 1
            return []
        out = judged & (np.abs(np.where(judged, z, 0.0)) > band.threshold)
        if not out.any():
            self.time_inside_s += new_s
            if self._dep is None:
                for name in self.aux_names:
                    if name in aux_window:
                        self._base.add(name, aux_stats(aux_window[name], band.sample_rate_hz))
                return []
            if t_end_s - self._dep.last_end_s >= band.window_s - 0.5 / band.sample_rate_hz:
                return [self._close(t_end_s)]
            return []
        self.time_outside_s += new_s
        self.windows_out += 1
        k = int(np.argmax(np.where(judged, np.abs(z), -1.0)))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = float(np.asarray(adev_dph, float)[k] / band.median_dph[k])
        taus = band.tau_s[out]
        if self._dep is not None:
            d = self._dep
            d.last_end_s = t_end_s
            d.windows_out += 1
            d.tau_lo_s, d.tau_hi_s = min(d.tau_lo_s, float(taus[0])), max(d.tau_hi_s, float(taus[-1]))
            if abs(z[k]) > d.peak_z:
                d.peak_z, d.peak_ratio, d.peak_tau_s = float(abs(z[k])), ratio, float(band.tau_s[k])
            return []
        shape = tau_shape(z, band.threshold)
        cause = self._cause(aux_window)
        first_new_s = t_end_s - new_s + 1.0 / band.sample_rate_hz  # the first sample of the new data
        self._dep = _Departure(first_new_s, t_end_s, t_end_s, float(taus[0]), float(taus[-1]),
                               float(abs(z[k])), ratio, float(band.tau_s[k]), shape, cause)
        idx = np.flatnonzero(out)
        if len(taus) == 1:
            span = f"tau {taus[0]:.4g} s"
        elif idx[-1] - idx[0] == len(idx) - 1:
            span = f"taus {taus[0]:.4g}..{taus[-1]:.4g} s"
        else:
            span = "taus " + ", ".join(f"{t:.4g}" for t in taus) + " s"
        msg = (f"left the model band at t = {t_end_s:.3f} s ({span} out): ADEV {ratio:.3g}x the model median "
               f"at tau {band.tau_s[k]:.4g} s (|z| {abs(z[k]):.3g} > {band.threshold:.3g}, family-wise "
               f"{band.alpha:g} per window); {shape}; likely cause: {cause}")
        return [Event(float(t_end_s), KIND, msg)]

    def _cause(self, aux_window: dict[str, np.ndarray]) -> str:
        best = None
        judged = False
        for name in self.aux_names:
            if name not in aux_window:
                continue
            s = aux_stats(aux_window[name], self.band.sample_rate_hz)
            sc = self._base.score(name, s)
            if sc is None:
                continue
            judged = True
            j = int(np.argmax(sc))
            if best is None or sc[j] > best[0]:
                best = (float(sc[j]), name, j, s[j], self._base.mean[name][j])
        if not judged or best is None:  # judged implies best is set
            return "no aux channel co-varies (no in-band window yet to compare the aux channels with)"
        if best[0] < COVARY_Z:
            return "no aux channel co-varies"
        score, name, j, now, before = best
        what, unit = AUX_MEANING.get(name, (name, ""))
        unit = unit + "/s" if STATS[j] == "slope" else unit
        return (f"{what} ({name} {STATS[j]} {now:.4g} {unit} vs {before:.4g} {unit} in band, "
                f"{score:.3g} sd)").replace("  ", " ")

    def _close(self, t_s: float) -> Event:
        d = self._dep
        assert d is not None, "called with a departure open"
        d.end_s = t_s
        self._done.append(d)
        self._dep = None
        return Event(float(t_s), KIND,
                     f"back in the model band at t = {t_s:.3f} s: out from t = {d.start_s:.3f} s to "
                     f"{d.last_end_s:.3f} s ({d.last_end_s - d.start_s:.4g} s, {d.windows_out} window(s) out), "
                     f"peak {d.peak_ratio:.3g}x the model median at tau {d.peak_tau_s:.4g} s; {d.shape}; "
                     f"likely cause: {d.cause}")

    def summary(self) -> dict:
        """Session summary: time (s) inside / outside the band / not judged (the new data
        of each window, attributed to its verdict), windows, the number of departures and
        each departure (start_s, end_s (None while open), taus, peak ratio, shape, cause),
        and the stated false-alarm rates (:func:`stated_rate`)."""
        deps = self._done + ([self._dep] if self._dep is not None else [])
        return {"time_inside_s": self.time_inside_s, "time_outside_s": self.time_outside_s,
                "time_unjudged_s": self.time_unjudged_s, "windows": self.windows,
                "windows_out": self.windows_out, "windows_unjudged": self.windows_unjudged,
                "n_departures": len(deps), "departures": [d.as_dict() for d in deps],
                "alpha_per_window": self.band.alpha, "threshold_abs_z": self.band.threshold,
                "left_out_effects": list(self.band.left_out)}


def stated_rate(band: ModelBand, hop_s: float) -> dict:
    """The stated false-alarm rates of a null run (gyro = its band model) at hop
    ``hop_s`` (s): ``alpha`` per window, ``per_hour_independent`` = alpha x 3600 /
    window_s (departures per hour were the windows independent, hop = window) and
    ``per_hour_max`` = alpha x 3600 / hop_s (a departure starts with a window out, and
    on average at most alpha of the windows are out)."""
    return {"alpha_per_window": band.alpha,
            "per_hour_independent": band.alpha * 3600.0 / band.window_s,
            "per_hour_max": band.alpha * 3600.0 / hop_s}
