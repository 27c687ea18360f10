"""A stationary baseline model from the recording itself, for `fogmon explain` without
``--model``: it describes the recording before any effect is judged, so it is fitted so
that an effect cannot inflate it (issue 11; docs/explain.md, "The baseline"):

1. the rate's least-squares fit on the recorded environment (temp_c drift terms,
   rot_dps scale-factor terms) is projected out - for the noise estimate only;
2. per octave tau up to the explain map's window / 4, the median over the map windows
   of their Allan variance (an effect confined to a few windows does not move it);
3. IEEE-952 terms by non-negative least squares on the relative Allan-variance error:
   N always, each of Q, B, K only when it lowers the chi-square by more than chance,
   R = 0 (a drift has a sign: the rate_ramp effect fits it); when the ADEV at the
   shortest tau lies below that fit (it bends below the white-noise slope: the
   sensor's own low-pass), white noise through a low-pass - a first-order Gauss-Markov
   term of short correlation time (a ``markov`` effect) or white noise through a
   Butterworth low-pass of order 1..4 (a ``lowpass_noise`` effect), whichever fits best,
   N then being the unfiltered white floor - is fitted together with them, kept only
   when it lowers the chi-square by more than chance; a fit that lies above the
   recording by more than chance at some tau is fitted again below it (FLOOR_ALPHA: an
   effect only adds Allan variance);
4. whole-record ADEV points at longer taus refine those terms while they stay
   consistent with them, but cannot add a term;
5. a second model adds the rate random walk K those longer taus show when the windows
   cannot refute it (:func:`baseline_models`): the record cannot tell its realisation
   from a drift, so explain judges named effects against both
   (``explainer.explain_without_model``).

Bias: the mean rate (deg/h). No effects but that filtered white noise: explaining
against this model asks "what in this recording is not stationary IEEE-952 noise, as
the sensor's low-pass shapes it?"."""
from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
from scipy.optimize import minimize, nnls
from scipy.stats import norm

from fogmon.davar.batch import oadev
from fogmon.davar.theory import POWERS, adev_model, avar_terms_to_coefficients
from fogmon.errors import FogmonError
from fogmon.formats.recording import Recording
from fogmon.sim import effects as fx
from fogmon.sim.model import Effect, Noise, SensorModel, validate_effect, validate_model
from fogmon.sim.noise import ar1_adev_exact, lowpass_adev_exact


def curve_noise_fit(tau_s: np.ndarray, adev_dph: np.ndarray, edf: np.ndarray | None = None,
                    edf_cap: float = 50.0, ramp: bool = True, terms: tuple[str, ...] | None = None,
                    lowpass_unit: np.ndarray | None = None, cap: np.ndarray | None = None) -> dict[str, float]:
    """IEEE-952 coefficients (Q arcsec, N deg/sqrt(h), B deg/h, K deg/h/sqrt(h), R deg/h^2)
    minimizing sum_i w_i (model_avar_i / avar_i - 1)^2 over the taus, all A_n >= 0, with
    w_i = min(edf_i, edf_cap) / edf_cap: equal weight wherever the point is well
    determined, less at the few-EDF longest taus. With ``lowpass_unit`` (the Allan
    variance of a unit-variance low-pass term at each tau, :func:`lowpass_unit_avar`)
    that term's variance is fitted with them and returned as ``lowpass_sigma_dph``.
    With ``cap`` the model's Allan variance stays at most ``cap`` x the data's at each
    tau (:func:`floor_caps`)."""
    ok = np.isfinite(adev_dph) & (adev_dph > 0)
    tau, av = np.asarray(tau_s)[ok], np.asarray(adev_dph)[ok] ** 2
    if edf is None:
        w = np.ones(len(tau))
    else:
        e = np.minimum(np.asarray(edf, dtype=float)[ok], edf_cap)
        w = np.sqrt(e / max(float(np.max(e)), 1e-300))
    cols = tau[:, None] ** POWERS[None, :]
    if lowpass_unit is not None:
        cols = np.column_stack((cols, np.asarray(lowpass_unit)[ok]))
    X = cols / av[:, None] * w[:, None]
    if not ramp:  # R left at 0 (a drift has a sign: it is the rate_ramp effect's to fit)
        X[:, 4] = 0.0
    if terms is not None:
        X[:, [i for i, nm in enumerate(NAMES) if nm not in terms]] = 0.0
    scale = np.max(np.abs(X), axis=0)
    scale[scale == 0] = 1.0
    a, _ = nnls(X / scale, w)
    if cap is not None:
        # rows of X are cols / av * w: model / av <= cap is (X a)_i <= cap_i w_i
        C, c = X / scale / w[:, None], np.asarray(cap, dtype=float)[ok]
        if np.any(C @ a > c):
            a = _capped_nnls(X / scale, w, C, c)
    a = a / scale
    coef = avar_terms_to_coefficients(a[:5])
    out = dict(zip(("Q_arcsec", "N_dpsh", "B_dph", "K_dphsh", "R_dphh"), map(float, coef), strict=True))
    if lowpass_unit is not None:
        out["lowpass_sigma_dph"] = math.sqrt(float(a[5]))
    return out


def _capped_nnls(X: np.ndarray, w: np.ndarray, C: np.ndarray, c: np.ndarray) -> np.ndarray:
    """argmin ||X a - w||^2 over a >= 0 with C a <= c (a convex quadratic programme; a = 0
    is feasible), by SLSQP."""
    fin = np.isfinite(c)
    cons = [{"type": "ineq", "fun": lambda a: c[fin] - C[fin] @ a, "jac": lambda a: -C[fin]}] if fin.any() else []
    r = minimize(lambda a: float(np.sum((X @ a - w) ** 2)), np.zeros(X.shape[1]),
                 jac=lambda a: 2.0 * X.T @ (X @ a - w), bounds=[(0.0, None)] * X.shape[1],
                 constraints=cons, method="SLSQP", options={"ftol": 1e-12, "maxiter": 500})
    return np.maximum(r.x, 0.0)


def floor_caps(edf: np.ndarray, z: float) -> np.ndarray:
    """Per tau the largest model / data Allan-variance ratio whose Wilson-Hilferty z
    (:func:`_wh_z` of data / model, ``edf`` degrees of freedom) is still >= -``z``: a model
    above it is noisier than the recording there by more than chance (inf when ``edf``
    is too small to bound it)."""
    v = 2.0 / (9.0 * np.maximum(np.asarray(edf, dtype=float), 0.5))
    b = 1.0 - v - z * np.sqrt(v)
    with np.errstate(divide="ignore"):
        return np.where(b > 0, 1.0 / np.maximum(b, 1e-300) ** 3, np.inf)


def model_avar(tau_s: np.ndarray, fit: dict[str, float], lowpass_unit: np.ndarray | None = None) -> np.ndarray:
    """Allan variance ((deg/h)^2) at ``tau_s`` of a :func:`curve_noise_fit` result."""
    ieee = {k: v for k, v in fit.items() if k != "lowpass_sigma_dph"}
    av = adev_model(tau_s, **ieee) ** 2
    if lowpass_unit is not None:
        av = av + fit["lowpass_sigma_dph"] ** 2 * np.asarray(lowpass_unit)
    return av


def markov_unit_avar(tau_s: np.ndarray, sample_rate_hz: float, tau_c_s: float) -> np.ndarray:
    """Allan variance at ``tau_s`` (multiples of the sample interval) of a unit-variance
    sampled first-order Gauss-Markov process - white noise through a first-order
    low-pass, as the simulator's ``markov`` effect (exact, :func:`ar1_adev_exact`)."""
    m = np.maximum(np.round(np.asarray(tau_s) * sample_rate_hz), 1)
    return ar1_adev_exact(m, 1.0, tau_c_s, sample_rate_hz) ** 2


NAMES = ("Q", "N", "B", "K", "R")
#: A noise term joins the baseline only if it lowers the fit's chi-square by more than
#: this (the 99 % point of chi-square with 1 degree of freedom): a term the data cannot
#: tell from chance (flicker far below the white noise at every tau the record has)
#: stays 0 instead of being inflated by an effect or by scatter.
TERM_CHI2 = 6.63


def fit_chi2(av: np.ndarray, edf: np.ndarray, pred: np.ndarray) -> float:
    """Sum over taus of the Wilson-Hilferty z^2 of each Allan variance ``av`` against the
    fit's ``pred`` (:func:`model_avar`)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.array([_wh_z(a / p, e) if p > 0 else np.inf for a, p, e in zip(av, pred, edf, strict=True)])
    return float(np.sum(z ** 2))


#: The baseline's low-pass on the white noise is sought among shapes of different order:
#: a sampled first-order Gauss-Markov term (``markov``; correlation times from
#: LOWPASS_TAU_C_SAMPLES[0] to [1] sample intervals, first-order corners from 0.04 to 1.6 x
#: the sample rate) and white noise through a Butterworth low-pass of each order in
#: LOWPASS_ORDERS (``lowpass_noise``; cutoffs from LOWPASS_CUTOFF_FS[0] to [1] x the sample
#: rate), each beside the IEEE-952 terms, whose N is then the unfiltered white floor. Per
#: shape LOWPASS_GRID_N log-spaced points, the best refined by golden section on the log
#: of the parameter. A best fit at either end of its range is refused: at the fast end it
#: is white noise, at the slow end a slower process (a hump such as the G ring's
#: microseism, left to the effects). Each shape is charged TERM_CHI2 per parameter like a
#: noise term (LOWPASS_PARAMS: the markov term's correlation time and variance; a
#: Butterworth's cutoff, variance and order) and the least criterion wins. The order
#: counts: a first-order Gauss-Markov term beside white noise and a first-order
#: Butterworth beside white noise span the same spectra (one pole, a numerator in cos w)
#: but for the sign of the Nyquist term, so on a Gauss-Markov record they tie by chance
#: unless the Butterworth pays for its choice. A Butterworth is fitted without Q: beside
#: an unfiltered quantization noise, whose PSD rises to Nyquist, it would describe a
#: filter that leaves that noise alone (the G ring's decimation filter acts on both; the
#: ``bandwidth`` effect, over the whole rate, is what fits it). Its cutoff stays below
#: 0.45 x the sample rate: nearer Nyquist it only trims the shortest tau while its PSD's
#: zero at Nyquist, without a floor N, tells the Whittle tests that the record has no
#: power there (xio_fusion_z: 0.473 x fs, every mean-type test then out of scale).
LOWPASS_TAU_C_SAMPLES = (0.1, 4.0)
LOWPASS_CUTOFF_FS = (0.04, 0.45)
LOWPASS_ORDERS = (1, 2, 3, 4)
LOWPASS_GRID_N = 40
LOWPASS_PARAMS = {"markov": 2, "lowpass_noise": 3}


def low_pass_index(model: SensorModel) -> int | None:
    """Index in ``model.effects`` of the sensor's low-pass-filtered white noise: the first
    ``lowpass_noise`` term, or ``markov`` term whose correlation time lies in the
    baseline's low-pass range (LOWPASS_TAU_C_SAMPLES; a longer one is bias wander, not a
    filter), else None."""
    tc_max = LOWPASS_TAU_C_SAMPLES[1] / float(model.sample_rate_hz)
    return next((i for i, e in enumerate(model.effects) if e.kind == "lowpass_noise"
                 or (e.kind == "markov" and e.params["tau_c_s"] <= tc_max * (1 + 1e-9))), None)


def lowpass_unit_avar(tau_s: np.ndarray, sample_rate_hz: float, kind: str, shape: dict) -> np.ndarray:
    """Allan variance at ``tau_s`` of the unit-variance low-pass term ``kind`` with the
    parameters ``shape`` (the effect's, without sigma_dph): :func:`markov_unit_avar` or
    the exact ``lowpass_noise`` one (:func:`lowpass_adev_exact`)."""
    if kind == "markov":
        return markov_unit_avar(tau_s, sample_rate_hz, shape["tau_c_s"])
    m = np.maximum(np.round(np.asarray(tau_s) * sample_rate_hz), 1)
    return lowpass_adev_exact(m, 1.0, shape["cutoff_hz"], shape["order"], sample_rate_hz) ** 2


def _butterworth_shape(order: int, cutoff_hz: float) -> dict:
    return {"cutoff_hz": cutoff_hz, "order": order}


def _lowpass_shapes(sample_rate_hz: float) -> list[tuple[str, tuple[float, float], Callable[[float], dict]]]:
    """(kind, range of the searched parameter, parameter -> shape) of each low-pass shape."""
    tc = (LOWPASS_TAU_C_SAMPLES[0] / sample_rate_hz, LOWPASS_TAU_C_SAMPLES[1] / sample_rate_hz)
    fc = (LOWPASS_CUTOFF_FS[0] * sample_rate_hz, LOWPASS_CUTOFF_FS[1] * sample_rate_hz)
    out: list[tuple[str, tuple[float, float], Callable[[float], dict]]] = [
        ("markov", tc, lambda x: {"tau_c_s": x})]
    out += [("lowpass_noise", fc, functools.partial(_butterworth_shape, k)) for k in LOWPASS_ORDERS]
    return out


def _best_terms(tau_s: np.ndarray, av: np.ndarray, edf: np.ndarray, lowpass_unit: np.ndarray | None = None,
                optional: tuple[str, ...] = ("Q", "B", "K"), cap: np.ndarray | None = None
                ) -> tuple[float, dict[str, float], tuple[str, ...]]:
    """(criterion, coefficients, terms) of the term set, N always and each of
    ``optional`` only if the data need it, with the least chi-square (:func:`fit_chi2`)
    + TERM_CHI2 per term; :func:`curve_noise_fit` with R = 0 and weights by the full
    degrees of freedom, so that the fit and the chi-square that judges it agree; ``cap``:
    :func:`curve_noise_fit`'s."""
    best = None
    for k in range(1 << len(optional)):
        terms = ("N",) + tuple(nm for i, nm in enumerate(optional) if k >> i & 1)
        fit = curve_noise_fit(tau_s, np.sqrt(av), edf, edf_cap=np.inf, ramp=False, terms=terms,
                              lowpass_unit=lowpass_unit, cap=cap)
        crit = fit_chi2(av, edf, model_avar(tau_s, fit, lowpass_unit)) + TERM_CHI2 * len(terms)
        if best is None or crit < best[0]:
            best = (crit, fit, terms)
    assert best is not None  # the loop ran at least once
    return best


def _optional_terms(kind: str | None) -> tuple[str, ...]:
    """The IEEE-952 terms a fit beside a low-pass term ``kind`` (None: none) may add to N:
    a Butterworth (``lowpass_noise``) is fitted without Q (LOWPASS_TAU_C_SAMPLES' note)."""
    return ("B", "K") if kind == "lowpass_noise" else ("Q", "B", "K")


def _search_shape(tau_s: np.ndarray, av: np.ndarray, edf: np.ndarray, sample_rate_hz: float, kind: str,
                  bounds: tuple[float, float], shape_of: Callable[[float], dict]
                  ) -> tuple[float, dict[str, float], tuple[str, ...], str, dict] | None:
    """(criterion incl. LOWPASS_PARAMS[kind] x TERM_CHI2, coefficients, terms, kind, shape) of the
    best low-pass of one shape, or None when its best parameter is at an end of ``bounds``."""

    optional = _optional_terms(kind)

    def trial(ln_x: float) -> tuple[float, dict[str, float], tuple[str, ...]]:
        unit = lowpass_unit_avar(tau_s, sample_rate_hz, kind, shape_of(math.exp(ln_x)))
        c, f, t = _best_terms(tau_s, av, edf, unit, optional)
        return c + LOWPASS_PARAMS[kind] * TERM_CHI2, f, t

    grid = [math.log(x) for x in np.geomspace(*bounds, LOWPASS_GRID_N)]
    i = min(range(len(grid)), key=lambda j: trial(grid[j])[0])
    if i in (0, len(grid) - 1):
        return None
    lo, hi = grid[i - 1], grid[i + 1]
    r = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(20):  # golden section on the log of the parameter
        c, d = hi - r * (hi - lo), lo + r * (hi - lo)
        if trial(c)[0] < trial(d)[0]:
            hi = d
        else:
            lo = c
    ln_x = min((grid[i], (lo + hi) / 2.0), key=lambda x: trial(x)[0])
    return (*trial(ln_x), kind, shape_of(math.exp(ln_x)))


def parsimonious_fit(tau_s: np.ndarray, av: np.ndarray, edf: np.ndarray, sample_rate_hz: float
                     ) -> tuple[dict[str, float], tuple[str, ...], tuple[str, dict] | None]:
    """The terms the data need (:func:`_best_terms`) and, when the shortest tau's Allan
    variance lies below that fit (the ADEV bends below the white-noise slope), low-pass
    filtered white noise fitted with them: of the shapes of :func:`_lowpass_shapes` the
    one with the least criterion, kept only if its best parameter is inside its range and
    it lowers the criterion by more than LOWPASS_PARAMS[kind] x TERM_CHI2.
    Returns (coefficients, with ``lowpass_sigma_dph`` when the low-pass is kept, terms,
    (effect kind, its parameters but sigma) or None)."""
    crit, fit, terms = _best_terms(tau_s, av, edf)
    if not av[0] < model_avar(tau_s[:1], fit)[0]:
        return fit, terms, None
    found = [r for kind, bounds, shape_of in _lowpass_shapes(sample_rate_hz)
             if (r := _search_shape(tau_s, av, edf, sample_rate_hz, kind, bounds, shape_of)) is not None]
    if not found:
        return fit, terms, None
    best = min(found, key=lambda r: r[0])
    if best[0] < crit:
        return best[1], best[2], (best[3], best[4])
    return fit, terms, None


#: A whole-record ADEV point beyond the windows' taus joins the baseline fit only while its
#: Allan variance is within this many standard deviations (Wilson-Hilferty scale) of
#: the fit so far: beyond it a non-stationary effect, not noise, is what it measures.
EXTEND_Z = 3.0


def _wh_z(ratio: float, edf: float) -> float:
    """Wilson-Hilferty z of an Allan-variance ratio (data / model) with ``edf`` degrees of
    freedom: chi2/edf has cube root ~ N(1 - 2/(9 edf), 2/(9 edf))."""
    v = 2.0 / (9.0 * max(edf, 0.5))
    return (ratio ** (1.0 / 3.0) - (1.0 - v)) / math.sqrt(v)


def robust_avar(y: np.ndarray, ok: np.ndarray, sample_rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tau s, Allan variance (deg/h)^2, degrees of freedom) at octave taus up to a
    window / 4: per tau the median over the explain map's windows (duration / 8, hop /
    4), so an effect confined to a few windows (a step, a transient, a glitch) does not
    raise it, scaled by the mean / median of a chi-square whose degrees of freedom
    ``edf_w`` come from the windows' own robust scatter (Wilson-Hilferty: cube-root
    CV^2 = 2 / (9 edf_w)). The median's degrees of freedom: edf_w x (2 / pi) x the
    number of independent windows (windows / 4: a hop is a quarter window)."""
    from fogmon.explain.mismatch import log_avar, make_grid

    grid = make_grid(len(y), sample_rate_hz)
    cell, _ = log_avar(np.where(ok, y, np.nan), ok, grid)
    out = np.full(len(grid.m), np.nan)
    edf = np.full(len(grid.m), np.nan)
    for j in range(len(grid.m)):
        c = cell[:, j][np.isfinite(cell[:, j])]
        if len(c) < 3:
            continue
        a = np.exp(c)
        med = float(np.median(a))
        u = (a / med) ** (1.0 / 3.0)
        cv = 1.4826 * float(np.median(np.abs(u - np.median(u))))
        v = min(cv * cv, 0.3)  # = 2 / (9 edf_w)
        out[j] = med / (1.0 - v) ** 3
        edf[j] = 2.0 / (9.0 * max(v, 1e-9)) * (2.0 / math.pi) * max(len(c) / 4.0, 1.0)
    return grid.tau_s, out, edf


#: Unit-coefficient parameter sets of the aux-driven mean effects projected out before
#: the baseline noise is estimated (the catalogue's thermal_drift and scale_factor).
_AUX_UNITS: dict[str, list[tuple[str, dict]]] = {
    "temp_c": [("thermal_drift", {"k0_poly_dph": [0.0, 1.0]}), ("thermal_drift", {"k0_poly_dph": [0.0, 0.0, 1.0]}),
               ("thermal_drift", {"k1_pos": 1.0}), ("thermal_drift", {"k1_neg": 1.0}),
               ("thermal_drift", {"k2_pos": 1.0}), ("thermal_drift", {"k2_neg": 1.0})],
    "rot_dps": [("scale_factor", {"ppm": 1.0}), ("scale_factor", {"asym_ppm": 1.0})],
}
_THERMAL_ZERO = {"k0_poly_dph": [], "k1_pos": 0.0, "k1_neg": 0.0, "k2_pos": 0.0, "k2_neg": 0.0}


def aux_projected(y: np.ndarray, ok: np.ndarray, t_s: np.ndarray, aux: dict, sample_rate_hz: float) -> np.ndarray:
    """``y`` minus its least-squares fit on the recorded environment (temperature drift
    terms of temp_c, scale-factor terms of rot_dps, each as the simulator defines them):
    what the stationary noise estimate must see. Unchanged without varying aux
    channels. Only the noise estimate uses it; the effects are judged afterwards."""
    cols = []
    for ch, units in _AUX_UNITS.items():
        a = aux.get(ch)
        if a is None or not np.nanstd(a) > 0:
            continue
        a = np.interp(t_s, t_s[np.isfinite(a)], a[np.isfinite(a)])
        for kind, p in units:
            params = {**_THERMAL_ZERO, **p} if kind == "thermal_drift" else {"ppm": 0.0, "asym_ppm": 0.0, **p}
            cols.append(fx.mean_rate_dph(validate_effect(kind, params, "baseline"), t_s, {ch: a}, sample_rate_hz))
    if not cols:
        return y
    X = np.column_stack([np.ones(len(y)), *cols])[ok]
    beta, *_ = np.linalg.lstsq(X, y[ok], rcond=None)
    out = y.copy()
    out[ok] = y[ok] - X @ beta
    return out


def robust_noise_fit(y: np.ndarray, ok: np.ndarray, sample_rate_hz: float
                     ) -> tuple[dict[str, float], tuple[str, dict] | None, dict[str, float] | None]:
    """IEEE-952 Q, N, B, K (R = 0: a drift is the rate_ramp effect's) of the recording's
    stationary noise and, when the sensor's low-pass shows, the term of its filtered
    white noise (``lowpass_sigma_dph`` in the coefficients, and (effect kind, its
    parameters but sigma), else None), fitted so that an effect does not inflate them:
    :func:`curve_noise_fit` to the window-median Allan variance (:func:`robust_avar`) at
    the windows' taus, with the terms those robust points need
    (:func:`parsimonious_fit`; fitted again below the recording when it lies above it by
    more than chance, FLOOR_ALPHA), refined with the whole-record ADEV at longer taus, in
    order, while each point stays within EXTEND_Z of the windows' fit. The long taus only
    refine: a term only they would need (what a periodic term, a drift or a step does
    there as well) is not added - it is left for the effects and the mismatch map to
    judge. Third: the same fit with a rate random walk K that only the long taus show
    (:func:`_walk_from_long_taus`), or None: the alternative null a drift is judged
    against (:func:`baseline_models`)."""
    whole = oadev(y, sample_rate_hz, taus="octave", valid=ok, alpha=0)
    tau_w, av_w, edf_w = robust_avar(y, ok, sample_rate_hz)
    nw = len(tau_w)
    keep = np.isfinite(av_w)
    tau, av, edf = list(tau_w[keep]), list(av_w[keep]), list(edf_w[keep])
    fit0, terms, lowpass = parsimonious_fit(np.array(tau), np.array(av), np.array(edf), sample_rate_hz)

    def unit(taus):
        return None if lowpass is None else lowpass_unit_avar(np.asarray(taus), sample_rate_hz, *lowpass)

    capped = _floor_violated(np.array(tau), np.array(av), np.array(edf), fit0, unit(tau), sample_rate_hz)
    if capped:  # the terms again, the model kept below the recording (FLOOR_ALPHA)
        optional = _optional_terms(None if lowpass is None else lowpass[0])
        _, fit0, terms = _best_terms(np.array(tau), np.array(av), np.array(edf), unit(tau), optional,
                                     cap=_floor_cap(np.array(tau), np.array(edf), sample_rate_hz))
    walk = None if "K" in terms else _walk_from_long_taus(np.array(tau), np.array(av), np.array(edf), whole, nw,
                                                            fit0, terms, unit, sample_rate_hz)
    cap = _floor_cap if capped else None

    def refined(fit: dict[str, float], terms: tuple[str, ...]) -> dict[str, float]:
        t, a, e = list(tau), list(av), list(edf)
        for j in range(nw, len(whole.tau_s)):
            aj, ej = float(whole.adev_dph[j]) ** 2, float(whole.edf[j])
            pred = float(model_avar(whole.tau_s[j:j + 1], fit, unit(whole.tau_s[j:j + 1]))[0])
            if not (np.isfinite(aj) and pred > 0) or _wh_z(aj / pred, ej) > EXTEND_Z:
                break
            t.append(float(whole.tau_s[j]))
            a.append(aj)
            e.append(ej)
        return curve_noise_fit(np.array(t), np.sqrt(np.array(a)), np.array(e), edf_cap=np.inf, ramp=False,
                               terms=terms, lowpass_unit=unit(t),
                               cap=None if cap is None else cap(np.array(t), np.array(e), sample_rate_hz))
    return refined(fit0, terms), lowpass, None if walk is None else refined(*walk)


def _walk_from_long_taus(tau_s: np.ndarray, av: np.ndarray, edf: np.ndarray, whole, nw: int,
                         fit: dict[str, float], terms: tuple[str, ...], unit: Callable, sample_rate_hz: float
                         ) -> tuple[dict[str, float], tuple[str, ...]] | None:
    """(coefficients, terms) with a rate random walk K added, or None: the windows' taus
    (up to duration / 32) are too short to see a K that the whole record's long taus show,
    and a walk left out of the null is then named as the ramps, warm-ups and steps its
    realisation looks like. K joins when the fit with it, over the windows' points and
    every whole-record point beyond them, (1) lowers the chi-square (:func:`fit_chi2`) by
    more than TERM_CHI2, (2) follows every long point within EXTEND_Z (a walk explains
    them all; a drift's tau^+1 rise or a periodic term's hump is left to the effects) and
    (3) stays below the window-median Allan variance (FLOOR_ALPHA, as the windows' fit):
    an effect confined to some windows (a step) raises the long taus but not the
    windows' medians, which then refuse a walk as large as the step."""
    long = [j for j in range(nw, len(whole.tau_s))
            if np.isfinite(whole.adev_dph[j]) and whole.adev_dph[j] > 0 and whole.edf[j] > 0]
    if not long:
        return None
    t_all = np.concatenate((tau_s, whole.tau_s[long]))
    a_all = np.concatenate((av, whole.adev_dph[long] ** 2))
    e_all = np.concatenate((edf, whole.edf[long]))
    with_k = (*terms, "K")
    fit_k = curve_noise_fit(t_all, np.sqrt(a_all), e_all, edf_cap=np.inf, ramp=False, terms=with_k,
                            lowpass_unit=unit(t_all))
    pred_k = model_avar(t_all, fit_k, unit(t_all))
    if not fit_k["K_dphsh"] > 0 or fit_chi2(a_all, e_all, model_avar(t_all, fit, unit(t_all))) - fit_chi2(
            a_all, e_all, pred_k) <= TERM_CHI2:
        return None
    n = len(tau_s)
    if any(abs(_wh_z(a / p, e)) > EXTEND_Z for a, p, e in zip(a_all[n:], pred_k[n:], e_all[n:], strict=True)):
        return None
    if _floor_violated(tau_s, av, edf, fit_k, unit(tau_s), sample_rate_hz):
        return None
    return fit_k, with_k


#: The stationary noise lies below the recording at every tau: an effect (a vibration, a
#: transient, a step) only adds Allan variance. A fit whose Allan variance lies above the
#: window-median one at some tau by more than chance - a Wilson-Hilferty z below the
#: FLOOR_ALPHA family-wise point over the taus (one-sided, Bonferroni: 3.17 for 13 taus) -
#: has been pulled up by what no IEEE-952 term follows (a vehicle's sway, a level that
#: rises towards Nyquist), and is fitted again with its Allan variance at most
#: FLOOR_CAP_Z standard deviations above the recording's at every tau
#: (:func:`floor_caps`); the recording's excess is then left to the effects and the
#: mismatch map. (A cap at the trigger itself would let the fit sit at -3 standard deviations
#: at every long tau at once: psins_rlg_z, N 0.033 deg/sqrt(h) where its long taus read 0.019.)
FLOOR_ALPHA = 0.01
FLOOR_CAP_Z = 1.0


def _floor_judged(tau_s: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """The taus where the floor is judged: from 1 / (2 x LOWPASS_CUTOFF_FS[0]) samples on
    (12.5). At shorter taus a sensor's low-pass (or a decimation filter: the ``bandwidth``
    effect) may lower the Allan variance - an effect that removes variance - so a fit
    above the recording there is no sign of a misfit (the G ring's decimation filter,
    z -5.6 at its shortest tau; a dip between its humps at 8 samples)."""
    return np.asarray(tau_s) * sample_rate_hz >= 0.5 / LOWPASS_CUTOFF_FS[0]


def _floor_violated(tau_s: np.ndarray, av: np.ndarray, edf: np.ndarray, fit: dict[str, float],
                    lowpass_unit: np.ndarray | None, sample_rate_hz: float) -> bool:
    """Whether ``fit`` lies above the Allan variance ``av`` by more than chance at some
    judged tau (:func:`_floor_judged`; FLOOR_ALPHA family-wise over them)."""
    judged = _floor_judged(tau_s, sample_rate_hz)
    if not judged.any():
        return False
    pred = model_avar(tau_s, fit, lowpass_unit)[judged]
    return bool(np.any(pred > av[judged] * floor_caps(edf[judged], float(norm.isf(FLOOR_ALPHA / judged.sum())))))


def _floor_cap(tau_s: np.ndarray, edf: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """The refit's bound (model / data Allan variance) per tau: FLOOR_CAP_Z at the judged
    taus, none at the others."""
    return np.where(_floor_judged(tau_s, sample_rate_hz), floor_caps(edf, FLOOR_CAP_Z), np.inf)


def baseline_model(rec: Recording) -> SensorModel:
    """Stationary IEEE-952 model fitted to ``rec`` robustly (:func:`robust_noise_fit` of
    :func:`aux_projected`), with the sensor's low-pass-filtered white noise as a
    ``markov`` or ``lowpass_noise`` effect when the fit found it; bias the mean rate (deg/h)."""
    return baseline_models(rec)[0]


def baseline_models(rec: Recording) -> tuple[SensorModel, SensorModel | None]:
    """:func:`baseline_model` and, when the whole record's long taus show a rate random
    walk the windows are too short to see (:func:`_walk_from_long_taus`), the same
    model with that walk's K (else None): the record cannot tell such a walk's
    realisation from a drift (a ramp, a warm-up, a step), so a drift named against the
    first is judged against the second too (``explainer.explain_without_model``)."""
    blk = rec.to_block()
    y = blk.error_rate_dph
    ok = blk.valid & np.isfinite(y)
    if ok.sum() < 64:
        raise FogmonError(f"{rec.name}: too few valid samples ({int(ok.sum())}) to fit a baseline model")
    rec.check_changes()
    vals, lowpass, walk = robust_noise_fit(aux_projected(y, ok, blk.t_s, blk.aux, rec.sample_rate_hz), ok,
                                           rec.sample_rate_hz)
    bias = float(np.mean(y[ok]))

    def model(vals: dict[str, float]) -> SensorModel:
        vals = dict(vals)
        sigma = vals.pop("lowpass_sigma_dph", 0.0)
        if not (any(vals.values()) or sigma):
            raise FogmonError(f"{rec.name}: no IEEE-952 noise term found for a baseline model")
        effects = [] if lowpass is None or not sigma else [Effect(lowpass[0], {**lowpass[1], "sigma_dph": sigma})]
        return validate_model(SensorModel(rec.sample_rate_hz, bias, Noise(**vals), effects,
                                          {"origin": f"fogmon explain baseline fitted from {rec.name}"}))
    return model(vals), None if walk is None else model(walk)
