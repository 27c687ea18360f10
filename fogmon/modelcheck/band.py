"""The model's dynamic-Allan-deviation band for one window length and tau set
(docs/modelcheck.md): what the live ADEV of a window of ``window_n`` samples looks like
when the gyro is exactly its noise model.

Built by a parametric bootstrap: ``replicates`` windows simulated from the model's
stationary stochastic part (:func:`band_model`), each through the DAVAR engine's
overlapping-ADEV estimator at the live engine's averaging factors m. The statistics are
those of ``fogmon explain`` (fogmon.explain.mismatch.build_null, a one-window map): per
tau the mean Allan variance and the spread of u = (avar / mean)^(1/3) (Wilson-Hilferty),
a live window's z = (u - mean u) / (sd sqrt(1 + 1/B)), and a family-wise threshold over
the taus of one window from a Gumbel law fitted to the replicates' leave-one-out
max |z|. The replicate matrix is cached on disk (fogmon.modelcheck.cache).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

import fogmon.modelcheck.cache as cache
from fogmon.errors import FogmonError
from fogmon.sim.model import EFFECT_KINDS, Effect, SensorModel, model_to_dict, validate_model

if TYPE_CHECKING:
    from fogmon.explain.mismatch import Null

# fogmon.explain.mismatch and fogmon.sim (scipy.ndimage, scipy.signal: a second of start-up)
# are imported inside the functions that use them: a run without a model never needs them

#: Effect natures the band holds: stationary random processes the simulator makes from
#: the model alone (``markov``, ``lowpass_noise``, ``vibration_lines``: "noise"; ``bandwidth``:
#: "filter").
#: Effects that need an aux channel or follow a time schedule are left out.
BAND_NATURES = ("noise", "filter")

#: Bootstrap windows by default: at window 2^16 with white, flicker and random-walk noise
#: about 0.1 s of CPU per replicate on the loaded 2-core test machine (10.5 s in all;
#: docs/modelcheck.md, benchmarks/bench_modelcheck.py), once per model and window thanks
#: to the cache; the threshold from 100 maxima varies by about +-0.1 in z between seeds.
DEFAULT_REPLICATES = 100


def band_effects(model: SensorModel) -> tuple[list[Effect], list[str]]:
    """(effects the band holds, kinds left out): kept are those of nature ``BAND_NATURES``
    that need no aux channel."""
    kept: list[Effect] = []
    left: list[Effect] = []
    for e in model.effects:
        spec = EFFECT_KINDS[e.kind]
        (kept if spec.aux is None and spec.nature in BAND_NATURES else left).append(e)
    return kept, [e.kind for e in left]


def band_model(model: SensorModel, sample_rate_hz: float) -> SensorModel:
    """The model's stationary stochastic part at ``sample_rate_hz`` (Hz): its bias, IEEE-952
    noise and the effects of :func:`band_effects`; no meta."""
    full = validate_model(SensorModel(sample_rate_hz, model.bias_dph, model.noise, model.effects, {}),
                          f"model at the live {sample_rate_hz:g} Hz")  # errors name the file's effect numbers
    return SensorModel(full.sample_rate_hz, full.bias_dph, full.noise, band_effects(full)[0], {})


def theory_adev_dph(model: SensorModel, m: np.ndarray, sample_rate_hz: float,
                    duration_s: float) -> np.ndarray | None:
    """Exact expected ADEV (deg/h, sqrt of the mean Allan variance) of the simulator's
    band model at averaging factors m, for a simulation of ``duration_s`` s (it sets the
    flicker generator's longest correlation time); None when the model holds an effect
    without a closed form here (bandwidth filter, vibration lines)."""
    from fogmon.sim.noise import ar1_adev_exact, default_flicker_tau_hi_s, flicker_adev_exact, lowpass_adev_exact

    bm = band_model(model, sample_rate_hz)
    sample_rate_hz = float(sample_rate_hz)
    m = np.asarray(m, dtype=float)
    tau = m / sample_rate_hz
    nz = bm.noise
    step = nz.K_dphsh / 60.0 * math.sqrt(1.0 / sample_rate_hz)  # random-walk step, deg/h
    avar = (3.0 * nz.Q_arcsec ** 2 / tau ** 2 + (60.0 * nz.N_dpsh) ** 2 / tau
            + step ** 2 * (2.0 * m * m + 1.0) / (6.0 * m) + (nz.R_dphh / 3600.0) ** 2 * tau ** 2 / 2.0)
    if nz.B_dph > 0:
        avar = (
            avar
            + flicker_adev_exact(m, nz.B_dph, sample_rate_hz, default_flicker_tau_hi_s(sample_rate_hz, duration_s)) ** 2
        )
    for e in bm.effects:
        p = e.params
        if e.kind == "markov":
            avar = avar + ar1_adev_exact(m, p["sigma_dph"], p["tau_c_s"], sample_rate_hz) ** 2
        elif e.kind == "lowpass_noise":
            avar = avar + lowpass_adev_exact(m, p["sigma_dph"], p["cutoff_hz"], p["order"], sample_rate_hz) ** 2
        else:
            return None
    return np.sqrt(avar)


def window_log_avar(y: np.ndarray, m: np.ndarray) -> np.ndarray:
    """ln overlapping Allan variance ((deg/h)^2) of one gap-free window ``y`` (deg/h) at
    averaging factors m: the DAVAR engine's estimator (every term, sum of squared terms
    / 2 m^2 count), by numpy prefix sums of y - mean (equal to ``oadev`` to rounding)."""
    s = np.concatenate(([0.0], np.cumsum(y - y.mean())))
    n = len(y)
    out = np.empty(len(m))
    for j, mj in enumerate(np.asarray(m, dtype=np.int64)):
        d = s[2 * mj:] - 2.0 * s[mj:n + 1 - mj] + s[:n + 1 - 2 * mj]
        out[j] = np.log(np.dot(d, d) / (2.0 * mj * mj * len(d)))
    return out


def replicate_log_avar(model: SensorModel, window_n: int, m: np.ndarray, replicates: int,
                       seed: int) -> np.ndarray:
    """ln Allan variance ((deg/h)^2), replicates x taus: ``replicates`` independent
    simulations of ``model`` (its own sample rate) of ``window_n`` samples each, seeds
    spawned from ``seed``."""
    from fogmon.sim.simulate import iter_simulate

    sample_rate_hz = model.sample_rate_hz
    seeds = np.random.SeedSequence(seed).generate_state(replicates, np.uint64)
    out = np.empty((replicates, len(m)))
    for b, sb in enumerate(seeds):
        (blk,) = iter_simulate(model, duration_s=window_n / sample_rate_hz, seed=int(sb), chunk_samples=window_n)
        out[b] = window_log_avar(blk.rate_dph, m)
    return out


def loo_max_abs_z(L: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Each replicate's max over taus of |z| against the other B - 1 replicates (mean
    and sd of u = (avar / exp(mu))^(1/3) without it): the law of a new window's max |z|.
    (``build_null`` keeps the sd of all B, right when it is pooled over many windows;
    with B values per tau a replicate in its own sd would lower the threshold.)"""
    B = L.shape[0]
    U = np.exp((L - mu[None]) / 3.0)
    d = U - U.mean(axis=0)
    ss_loo = np.maximum(np.sum(d * d, axis=0)[None] - d * d * B / (B - 1.0), 1e-300)
    z = d * B / (B - 1.0) / np.sqrt(ss_loo / (B - 2.0) * (1.0 + 1.0 / (B - 1.0)))
    return np.max(np.abs(z), axis=1)


@dataclass(frozen=True)
class ModelBand:
    """The model's DADEV band for windows of ``window_n`` samples at ``sample_rate_hz``
    (Hz) and averaging factors ``m`` (tau_s = m / rate, s). Per tau (deg/h):
    ``median_dph`` the bootstrap median ADEV, ``lo_dph``/``hi_dph`` the band at the
    family-wise level (a window whose ADEV leaves it at any tau is out of band: ``alpha``
    per window), ``theory_dph`` the exact expected ADEV where a closed form exists
    (else None). ``threshold``: |z| beyond it at any tau = out of band. ``left_out``:
    the model's effect kinds the band does not hold. ``cache_status``: how the
    replicates were obtained (read from / written to the cache, or why not)."""

    sample_rate_hz: float
    window_n: int
    m: np.ndarray
    alpha: float
    null: Null
    median_dph: np.ndarray
    theory_dph: np.ndarray | None
    left_out: tuple[str, ...]
    cache_status: str

    @classmethod
    def for_model(cls, model: SensorModel, sample_rate_hz: float, window_n: int, m: np.ndarray,
                  alpha: float = 0.01, replicates: int = DEFAULT_REPLICATES, seed: int = 0,
                  cache_dir: str | None = None) -> ModelBand:
        """Band of ``model`` for the live engine's window (``window_n`` samples) and
        averaging factors ``m`` at ``sample_rate_hz`` (Hz), family-wise ``alpha`` per
        window, from ``replicates`` bootstrap windows (seed ``seed``). The replicates are
        cached under ``cache_dir`` (default $XDG_CACHE_HOME/fogmon or ~/.cache/fogmon)."""
        if not 0.0 < alpha < 0.5:
            raise FogmonError(f"model band: alpha must be in (0, 0.5) per window, got {alpha!r}")
        if not (isinstance(replicates, (int, np.integer)) and replicates >= 8):
            raise FogmonError(f"model band: need at least 8 bootstrap replicates, got {replicates!r}")
        if not (isinstance(seed, (int, np.integer)) and seed >= 0):
            raise FogmonError(f"model band: seed must be a non-negative integer, got {seed!r}")
        m = np.asarray(m, dtype=np.int64)
        window_n = int(window_n)
        if len(m) == 0 or m.min() < 1 or 2 * m.max() > window_n:
            raise FogmonError(f"model band: averaging factors must be 1..{window_n // 2} for a window of "
                              f"{window_n} samples")
        bm = band_model(model, sample_rate_hz)
        key = cache.key({"model": model_to_dict(bm), "window_n": window_n, "m": m.tolist(),
                         "replicates": int(replicates), "seed": int(seed)})
        folder = cache.default_dir() if cache_dir is None else os.fspath(cache_dir)
        L = cache.load(folder, key, (int(replicates), len(m)))
        if L is not None:
            status = f"read from the cache {folder}"
        else:
            L = replicate_log_avar(bm, window_n, m, int(replicates), int(seed))
            status = cache.save(folder, key, L)
        from fogmon.explain.mismatch import Gumbel, build_null

        null = build_null(L[:, None, :], L, alpha)
        null = replace(null, gumbel=Gumbel.fit(loo_max_abs_z(L, null.mu[0])))
        median = np.median(np.sqrt(np.exp(L)), axis=0)
        theory = theory_adev_dph(model, m, sample_rate_hz, window_n / sample_rate_hz)
        return cls(float(sample_rate_hz), window_n, m, float(alpha), null, median, theory,
                   tuple(band_effects(model)[1]), status)

    @property
    def tau_s(self) -> np.ndarray:
        """Averaging times (s)."""
        return self.m / self.sample_rate_hz

    @property
    def window_s(self) -> float:
        """Window length (s)."""
        return self.window_n / self.sample_rate_hz

    @property
    def threshold(self) -> float:
        """Family-wise |z| threshold of one window (Gumbel 1 - alpha quantile)."""
        return self.null.threshold

    @property
    def mean_avar(self) -> np.ndarray:
        """Bootstrap mean Allan variance per tau ((deg/h)^2)."""
        return np.exp(self.null.mu[0])

    def adev_at_z(self, z: float) -> np.ndarray:
        """ADEV (deg/h) per tau whose z is ``z`` (0 where that lies below zero ADEV)."""
        infl = math.sqrt(1.0 + 1.0 / self.null.n_replicates)
        u = np.maximum(self.null.mu_u[0] + z * self.null.sd * infl, 0.0)
        return np.sqrt(self.mean_avar * u ** 3)

    @property
    def lo_dph(self) -> np.ndarray:
        """Lower edge of the band (deg/h) at the family-wise level."""
        return self.adev_at_z(-self.threshold)

    @property
    def hi_dph(self) -> np.ndarray:
        """Upper edge of the band (deg/h) at the family-wise level."""
        return self.adev_at_z(self.threshold)

    def z(self, adev_dph: np.ndarray) -> np.ndarray:
        """z per tau of a window's ADEV (deg/h, last axis over the band's taus: one
        window or a T x M map of them); NaN where the ADEV is NaN (no valid term), +inf
        where it is +inf (a huge sample)."""
        from fogmon.explain.mismatch import zscores

        a = np.asarray(adev_dph, dtype=float)
        with np.errstate(divide="ignore"):
            cell = np.log(a * a)
        return zscores(cell, cell, self.null)[0].reshape(a.shape)
