"""IEEE-952 noise-coefficient fit by iterated EDF-weighted NNLS (Fisher scoring).

Model sigma^2(tau) = sum_n A_n tau^n, n = -2..2, A_n >= 0 (theory.POWERS). Each
iteration solves a non-negative least-squares problem with weights
nu_i / (2 sigma_model_i^4) - the inverse variance of sigma_hat_i^2 under the model, with
nu_i the EDF of the noise mixture the model predicts at tau_i - which is Fisher scoring
for the chi-square likelihood (made robust by Tukey reweighting). The fit uses one tau
per octave of the grid it is given (``octave_subset``), so that identification does not
depend on how densely the grid samples the same information. Standard errors come from
the sandwich covariance of this estimator with the exact covariance of the Allan
variances across taus for that mixture (confidence.avar_relative_covariance); a term is
identifiable when its 95 % interval excludes zero. Every term also gets a one-sided 95 %
upper limit from the profile of the fit's own (extended quasi-) likelihood, rescaled for
the correlation across taus (``fit_avar``). The iterations run in numba
(fogmon/davar/scoring.py), one call per fitted curve.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from statistics import NormalDist

import numpy as np

from fogmon.davar.confidence import covariance_matrices, mixture_matrices
from fogmon.davar.profile import fit_full, score_limits
from fogmon.davar.result import CONFIDENCE, AdevResult, DadevResult
from fogmon.davar.scoring import fisher_scoring, mixture_edf
from fogmon.davar.taus import anchors
from fogmon.davar.termcheck import TermContradiction, contradictions, first_peak
from fogmon.davar.theory import NAMES, POWERS, avar_terms_to_coefficients

_K = NAMES.index("K_dphsh")  # the random walk's column
IDENTIFY_Z = 1.959964
"""A term is identifiable when A_n - IDENTIFY_Z * se(A_n) > 0 (95 % one-sided-ish)."""
_MAX_ITER = 50
_MAX_ROBUST_ITER = 30
_N_RUN_STARTS = 6
_RW_TOL = 1e-4  # robust weights converged
_ROBUST_RTOL = 1e-6  # model convergence while the robust weights still move
MISFIT_FLOOR = 0.1
"""Relative standard deviation of an Allan variance that the five terms may miss (model
inadequacy); added in quadrature to sqrt(2 / nu) when residuals are standardized for
the robust weights (not to the fit weights or the intervals)."""
BIRGE_GATE = 4.0
"""Reduced chi-square of the log residuals above which the fit estimates a model-inadequacy
variance (clean power-law records stay below it: a record the terms describe is fitted
with the pure EDF weights)."""
TUKEY_C = 4.685
"""Tukey biweight cut-off (95 % efficiency under normal residuals), in robust scale units."""
_RTOL = 1e-9
UPPER_CONFIDENCE = 0.95
"""One-sided confidence of every term's upper limit (``Coefficient.upper``)."""
_UPPER_Z = NormalDist().inv_cdf(UPPER_CONFIDENCE)  # 1.645


@dataclass(frozen=True)
class Coefficient:
    """One IEEE-952 coefficient (unit in the attribute name): estimate ``value``,
    interval ``lo``..``hi`` at the fit's confidence, ``identifiable`` False when the
    record cannot tell the term from zero (then ``value`` = ``lo`` = 0 and ``hi`` is
    ``upper``, or at a confidence above 90 % the profile interval's upper end where
    higher: ``_coefficients``; quote only ``upper``, as an upper limit). ``upper``: one-sided
    UPPER_CONFIDENCE (95 %) upper limit of the coefficient, never below the term's
    estimate in a fit that includes it (every term of an AdevResult fit; in a DadevResult
    fit only where not identifiable, else NaN). Scalars for an AdevResult fit, arrays
    over windows for a DadevResult fit."""

    value: np.ndarray | float
    lo: np.ndarray | float
    hi: np.ndarray | float
    identifiable: np.ndarray | bool
    upper: np.ndarray | float

    def __str__(self) -> str:
        if np.ndim(self.value):
            return f"Coefficient(windows={np.size(self.value)}, identifiable={int(np.sum(self.identifiable))})"
        if not self.identifiable:
            return f"not identifiable (< {self.upper:.4g}, 95 % upper limit)"
        return f"{self.value:.4g} [{self.lo:.4g}, {self.hi:.4g}]"


@dataclass(frozen=True)
class NoiseFit:
    """Fitted IEEE-952 coefficients. ``avar_terms`` holds A_n ((deg/h)^2 s^-n, n = -2..2,
    last axis), ``avar_se`` their standard errors; ``confidence`` the interval level.
    ``misfit`` (bool, shape of the fitted ``adev_dph``) marks the taus the robust fit
    rejected as not described by the five terms (periodic/vibration humps, steps);
    ``worst_ratio`` (>= 1, per window for a DADEV fit) is the largest factor between the
    model and the measured ADEV over the taus not flagged (NaN when nothing was fitted).
    ``contradicted`` (a whole-curve fit): the terms whose own ADEV the measured ADEV
    refutes (``termcheck``): a B, K or R there is not identifiable (its upper limit the
    ADEV's bound), a Q there is band-limited white angle noise, not quantization
    (``q_band_limited``); ``avar_terms`` and ``model_adev_dph`` stay the fit's estimate.
    ``quantized_count_arcsec`` (a whole-record fit, ``davar.record``): the angle count of
    an output whose samples lie on a lattice, where a white quantizer of that count would
    break the ADEV's bound on Q, so the bound does not hold for it (NaN otherwise).
    ``check_terms`` (a whole-curve fit whose ADEV took a rate ramp as deterministic,
    ``AdevResult.ramp_k``): the A_n the model check tests, the fit with K held at the
    ADEV's (``check_adev_dph``); None: ``avar_terms``."""

    Q_arcsec: Coefficient
    N_dpsh: Coefficient
    B_dph: Coefficient
    K_dphsh: Coefficient
    R_dphh: Coefficient
    avar_terms: np.ndarray
    avar_se: np.ndarray
    avar_upper: np.ndarray
    confidence: float
    misfit: np.ndarray
    worst_ratio: np.ndarray | float
    contradicted: tuple[TermContradiction, ...] = ()
    quantized_count_arcsec: float = float("nan")
    check_terms: np.ndarray | None = None

    @property
    def q_band_limited(self) -> bool:
        """The Q term's 1/tau slope does not reach the shortest tau: white angle noise of
        a band-limited (filtered, decimated) output, not a quantizer (``termcheck``)."""
        return any(c.name == "Q_arcsec" for c in self.contradicted)

    def model_adev_dph(self, tau_s) -> np.ndarray:
        """Model Allan deviation (deg/h) at ``tau_s`` (s); shape (..., len(tau_s))."""
        return _model_adev_dph(self.avar_terms, tau_s)

    def check_adev_dph(self, tau_s) -> np.ndarray:
        """The Allan deviation (deg/h) at ``tau_s`` (s) of the model the check against the
        measured ADEV tests (``check_terms``, else ``model_adev_dph``)."""
        return _model_adev_dph(self.avar_terms if self.check_terms is None else self.check_terms, tau_s)

    def coefficients(self) -> dict[str, Coefficient]:
        """Name (with unit) -> Coefficient, in the order Q, N, B, K, R."""
        return {n: getattr(self, n) for n in NAMES}


def _model_adev_dph(avar_terms: np.ndarray, tau_s) -> np.ndarray:
    """Allan deviation (deg/h) of the terms ``avar_terms`` (A_n, last axis) at ``tau_s``
    (s); shape (..., len(tau_s))."""
    tau = np.asarray(tau_s, dtype=np.float64)
    x = tau[..., None] ** POWERS
    return np.sqrt(np.einsum("...n,tn->...t", avar_terms, np.atleast_2d(x)).reshape(avar_terms.shape[:-1] + tau.shape))


def octave_subset(m, m_max: int) -> np.ndarray:
    """Indices (sorted) of the averaging factors ``m`` the fit uses: for each power of two
    2^k <= ``m_max`` (n / 4, the octave grid's last), the m nearest to it in log2 within
    half an octave. An octave grid is kept whole,
    "all" and 1/3-octave grids give (nearly) the octave grid, sparser grids are kept. Taus
    a fraction of an octave apart carry nearly the same information (their Allan variances
    correlate above 0.9): fitting them all with per-tau weights would count it again for
    every extra tau, so identification would depend on the grid's density."""
    lg = np.log2(np.asarray(m, dtype=np.float64))
    k = np.round(lg)
    k = np.where(k <= np.floor(np.log2(max(m_max, 1))), k, np.inf)
    order = np.lexsort((np.abs(lg - k), k))
    order = order[np.isfinite(k[order])]
    return np.sort(order[np.r_[True, np.diff(k[order]) != 0]]) if len(order) else order


class _NoiseModel:
    """Sampling statistics of the Allan variances of a record whose noise is the mixture a
    model A predicts (white rate noise where the model is still empty): EDF per tau
    (``__call__``, scaled for gaps); the mixture matrices of ``m`` and ``n_samples``
    computed once per fit, the cross-tau ones (``cov``, cached per grid: the correlation
    across taus, ``scoring.mixture_correlation``) only when first needed."""

    def __init__(self, tau, m, n_terms, n_samples: int):
        tau = np.asarray(tau, dtype=np.float64)
        self.x = tau[:, None] ** POWERS
        self.n_samples = n_samples
        self.mats = mixture_matrices(m, n_samples)
        full = np.maximum(n_samples - 2 * np.asarray(m) + 1, 1)
        self.full = full.astype(np.float64)
        self.gap_scale = (np.asarray(n_terms) / full).astype(np.float64)
        self.m = np.asarray(m, dtype=np.int64)
        self._cov: np.ndarray | None = None

    @property
    def cov(self) -> np.ndarray:
        """``confidence.covariance_matrices`` of the fitted taus, fetched on first use."""
        if self._cov is None:
            self._cov = covariance_matrices(self.m, self.n_samples)
        return self._cov

    def __call__(self, a: np.ndarray) -> np.ndarray:
        return mixture_edf(self.x, np.asarray(a, dtype=np.float64), self.mats, self.full, self.gap_scale)


def _scoring(x, cols, y, edf, rw, a=None, c2=0.0, rtol=_RTOL):
    """Fisher scoring with the terms ``cols`` (mask over the 5 columns of x), robust
    weights ``rw`` (0..1 per tau), EDF model ``edf`` and model-inadequacy variance ``c2``,
    from the terms ``a`` (default: the data as model), until the model moves less than
    ``rtol``: returns (A >= 0 over all 5 terms, model, nu at the final model)
    (``scoring.fisher_scoring``)."""
    from_data = a is None or not np.any(a[cols] > 0)
    a0 = np.zeros(5) if from_data else np.where(cols, a, 0.0)
    return fisher_scoring(x, cols, y, edf.mats, edf.full, edf.gap_scale, np.asarray(rw, dtype=np.float64), a0,
                          from_data, float(c2), rtol, _MAX_ITER)


def _starts(n: int) -> list[np.ndarray]:
    """Robust starting weights: all taus, then up to _N_RUN_STARTS evenly spread runs of
    half of them (so that a stretch the five terms cannot describe, e.g. a vibration
    hump, cannot pull every start)."""
    k = max((n + 1) // 2, min(n, 5))
    first = np.unique(np.linspace(0, n - k, min(n - k + 1, _N_RUN_STARTS)).round().astype(int))
    idx = np.arange(n)
    return [np.ones(n)] + [((idx >= i) & (idx < i + k)).astype(np.float64) for i in first]


@dataclass(frozen=True)
class CurveFit:
    """The fit of one Allan variance curve (``fit_curve``), over the 5 terms Q, N, B, K, R:
    ``a`` the five-term estimate A_n ((deg/h)^2 s^-n; NaN when nothing could be fitted),
    ``se`` its sandwich standard errors, ``identifiable`` (the term's 95 % profile
    interval excludes zero: ``score_z`` > IDENTIFY_Z, ``score_z`` the signed root of the
    score test of A_n = 0, NaN where not computed), ``lo``/``hi`` its two-sided profile interval at
    ``confidence`` (NaN where not computed), ``upper`` its one-sided UPPER_CONFIDENCE
    upper limit (NaN where not computed), ``misfit`` the taus (of the curve given) the
    five terms cannot describe; ``a_check`` the terms the model check tests where the
    curve's EDF took a ramp as deterministic (``fit_curve``'s ``ramp_k``), else None."""

    a: np.ndarray
    se: np.ndarray
    identifiable: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    upper: np.ndarray
    misfit: np.ndarray
    confidence: float
    score_z: np.ndarray
    a_check: np.ndarray | None = None


_LIMITS = ("none", "unidentified", "all")


def fit_curve(tau_s, avar, m, n_terms, n_samples: int, confidence: float = CONFIDENCE,
              limits: str = "all", ramp_k: float = np.nan) -> CurveFit:
    """Fit A_n >= 0 to one Allan variance curve (deg/h)^2 over ``tau_s`` (s) with averaging
    factors ``m`` and valid-term counts ``n_terms`` of a record of ``n_samples`` samples.

    On the taus of ``octave_subset`` (``profile.fit_full``): robust Fisher scoring with
    all five terms, iteratively reweighted by Tukey's biweight of the standardized log
    residuals z = ln(y / model) / sqrt(2 / nu + MISFIT_FLOOR^2) from each of the robust
    weight vectors of ``_starts`` (the least total Tukey loss wins, an earlier start ties;
    a start that rejects no tau ends the search; one keeping fewer than two taus has
    failed), with a model-inadequacy variance c2 (Paule-Mandel: the c2 >= 0 with
    sum rw r^2 / (v + c2) = degrees of freedom) where the kept taus' reduced chi-square
    exceeds BIRGE_GATE, else 0; the estimate is that of all five terms (a term the record
    cannot tell from zero still takes what it explains, so the others do not absorb it).
    Then for each term the generalized score test of A_n = c with every other term free
    and refitted (``profile.score_limits``): identifiable when A_n = 0 is rejected at
    IDENTIFY_Z (the 95 % two-sided interval excludes zero), the two-sided ``confidence``
    interval and the one-sided UPPER_CONFIDENCE upper limit where the test's signed root
    reaches the normal quantiles, read through the null distribution it has where the
    refit holds another term at its bound 0 (``profile.boundary_z``; every other term
    counts in a limit's variance at no less than its estimate). ``limits``: "all" terms' limits, only the "unidentified"
    ones' upper limit (the identification test for every term; ``lo``/``hi`` NaN), or
    "none" (no test: ``identifiable`` from the sandwich A_n - IDENTIFY_Z se_n > 0). Nothing is
    identifiable (A_n NaN) when fewer than 2 taus are usable or the robust weights reject
    all but one tau. ``ramp_k`` (finite: the curve's EDF took its rate ramp as
    deterministic beside a random walk of A_K = ramp_k, ``AdevResult.ramp_k``): ``a_check``
    is the fit with K held there and the other terms refitted, the model that EDF
    describes, for the model check (``adequacy.check_model``)."""
    if limits not in _LIMITS:
        raise ValueError(f"`limits` must be one of {', '.join(_LIMITS)}, got {limits!r}")
    tau = np.asarray(tau_s, dtype=np.float64)
    avar = np.asarray(avar, dtype=np.float64)
    ok = (np.asarray(n_terms) > 0) & np.isfinite(avar) & (avar > 0)
    misfit = np.zeros(len(tau), dtype=bool)
    nan = np.full(5, np.nan)
    failed = CurveFit(nan, nan, np.zeros(5, bool), nan, nan, nan, misfit, confidence, nan)
    if ok.sum() < 2:
        return failed
    use = np.flatnonzero(ok)
    use = use[octave_subset(np.asarray(m)[use], n_samples // 4)]
    if len(use) < 2:
        use = np.flatnonzero(ok)
    y, nt = avar[use], np.asarray(n_terms)[use]
    m_int = np.asarray(m, dtype=np.int64)[use]
    x = tau[use][:, None] ** POWERS
    edf = _NoiseModel(tau[use], m_int, nt, n_samples)
    found, a, se, rw, c2 = fit_full(
        x, y, edf.mats, edf.full, edf.gap_scale, edf.cov, np.array(_starts(len(y))), TUKEY_C, MISFIT_FLOOR**2,
        BIRGE_GATE, _RW_TOL, _MAX_ROBUST_ITER, _ROBUST_RTOL, _RTOL, _MAX_ITER)
    if not found:  # the robust weights reject all taus: nothing is identifiable
        return failed
    misfit[use] = rw == 0
    a_check = None
    if np.isfinite(ramp_k):
        held = a.copy()
        held[_K] = max(float(ramp_k), 0.0)
        cols = np.ones(5, dtype=bool)
        cols[_K] = False
        a_check = fisher_scoring(x, cols, y, edf.mats, edf.full, edf.gap_scale, rw, held, False, c2, _RTOL,
                                 _MAX_ITER)[0]
    rest = np.setdiff1d(np.flatnonzero(ok), use)
    if len(rest):
        misfit[rest] = _misfit_outside(a, tau[rest], avar[rest], np.asarray(m, dtype=np.int64)[rest],
                                       np.asarray(n_terms)[rest], n_samples)
    lo = hi = upper = nan
    if limits == "none":
        return CurveFit(a, se, a - IDENTIFY_Z * se > 0, lo, hi, upper, misfit, confidence, nan, a_check)
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    both = limits == "all"
    upper_z = sorted({z, _UPPER_Z}) if both else [_UPPER_Z]
    s0, lower, up = score_limits(x, y, edf.mats, edf.full, edf.gap_scale, edf.cov, rw, c2, a, se,
                                 np.ones(5, dtype=bool), IDENTIFY_Z, np.array([z] if both else []),
                                 np.array(upper_z), _ROBUST_RTOL, _MAX_ITER)
    ident = s0 > IDENTIFY_Z
    at = {q: up[:, i] for i, q in enumerate(upper_z)}
    upper = np.maximum(at[_UPPER_Z], a)
    if both:
        lo, hi = np.minimum(lower[:, 0], a), np.maximum(at[z], a)
    else:
        upper = np.where(ident, np.nan, upper)
    return CurveFit(a, se, ident, lo, hi, upper, misfit, confidence, s0, a_check)


def fit_avar(tau_s, avar, m, n_terms, n_samples: int,
             upper_limits: str = "none") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``fit_curve`` as (A_n, standard error of A_n, misfit mask over ``tau_s``, one-sided
    UPPER_CONFIDENCE upper limit of A_n for ``upper_limits`` "all" terms, the
    "unidentified" ones or "none": NaN where not computed)."""
    f = fit_curve(tau_s, avar, m, n_terms, n_samples, CONFIDENCE, upper_limits)
    return f.a, f.se, f.misfit, f.upper


def dense_grid_edf(a: np.ndarray, tau: np.ndarray, m: np.ndarray, n_terms: np.ndarray, n_samples: int) -> np.ndarray:
    """EDF per tau of the Allan variances of the noise mixture the model ``a`` predicts,
    exact (``_NoiseModel``) at up to taus.ANCHORS_PER_OCTAVE taus per octave and interpolated
    in log-log between them on denser grids: a mixture matrix costs ~12 ms per m, so the
    exact EDF of an "all" grid of 2^15 samples took 45 s; interpolated it is within 0.2 %
    of it (tests/davar/test_fit_covariance.py)."""
    full = np.maximum(n_samples - 2 * m + 1, 1)
    nu = anchored_edf(m, lambda i: _NoiseModel(tau[i], m[i], full[i], n_samples)(a))
    return nu * (np.asarray(n_terms) / full)


def anchored_edf(m: np.ndarray, edf_at: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """EDF per factor ``m`` from ``edf_at`` (the exact EDF at the given indices of ``m``)
    evaluated at the factors ``taus.anchors`` picks, interpolated in log-log between them
    (``dense_grid_edf``)."""
    lg = np.log2(m)
    anchor = anchors(m)
    return np.exp(np.interp(lg, lg[anchor], np.log(edf_at(anchor))))


def mixture_edf_row(a: np.ndarray, tau: np.ndarray, m: np.ndarray, n_samples: int) -> np.ndarray:
    """Gap-free EDF per tau of the Allan variances of ``n_samples`` samples whose noise is
    the mixture the model ``a`` (A_n for ``tau``'s unit) predicts, its ramp deterministic
    (``dense_grid_edf``); NaN where 2 m > n_samples: the EDF of the ADEV intervals."""
    m = np.asarray(m, dtype=np.int64)
    out = np.full(len(m), np.nan)
    ok = 2 * m <= n_samples
    if ok.any():
        full = n_samples - 2 * m[ok] + 1
        out[ok] = dense_grid_edf(np.asarray(a, dtype=np.float64), np.asarray(tau, dtype=np.float64)[ok], m[ok], full,
                                 n_samples)
    return out


def _misfit_outside(a: np.ndarray, tau: np.ndarray, avar: np.ndarray, m: np.ndarray, n_terms: np.ndarray,
                    n_samples: int) -> np.ndarray:
    """Taus outside the fitted subset that the fitted terms ``a`` cannot describe: the
    Tukey rejection of their log residual from the model, scaled by its sampling spread."""
    nu = dense_grid_edf(a, tau, m, n_terms, n_samples)
    z = np.log(avar / np.maximum(tau[:, None] ** POWERS @ a, 1e-300))
    return np.abs(z) / np.sqrt(2.0 / nu + MISFIT_FLOOR**2) >= TUKEY_C


_QUICK_RTOL = 1e-3  # model convergence of quick_avar_terms


def low_pass_taus(avar) -> int:
    """How many of the shortest taus of the Allan variance curve ``avar`` (ascending tau)
    lie below a low-pass's peak: the ADEV rises from the shortest tau and then stops
    rising (``termcheck.first_peak``, at least two taus after the peak), else 0."""
    peak = first_peak(np.asarray(avar, dtype=np.float64))
    return peak if peak <= len(avar) - 3 else 0


def quick_avar_terms(tau_s, avar, m, n_terms, n_samples: int) -> np.ndarray:
    """A_n >= 0 ((deg/h)^2 s^-n, n = -2..2) of a quick fit for the noise type of the
    confidence bounds: Fisher scoring of all five terms with the mixture-EDF weights on
    the taus of ``octave_subset``, to 1e-3 relative in the model, without the robust
    reweighting, elimination and intervals of ``fit_avar`` (~1 ms instead of 10-60 ms);
    zeros when fewer than 2 taus are usable. When the ADEV rises from the shortest tau and
    then stops rising (a low-pass: ``termcheck.first_peak``, with at least two taus after
    the peak), the taus before the peak are left out: no IEEE-952 term rises there, and
    fitted they become a ramp R whose deterministic share made the EDF of a filtered
    flicker floor 11,470 at 82 s of a 3000 s record (its flicker EDF ~ 40)."""
    tau = np.asarray(tau_s, dtype=np.float64)
    avar = np.asarray(avar, dtype=np.float64)
    ok = (np.asarray(n_terms) > 0) & np.isfinite(avar) & (avar > 0)
    use = np.flatnonzero(ok)
    use = use[octave_subset(np.asarray(m)[use], n_samples // 4)]
    use = use[low_pass_taus(avar[use]):]
    if len(use) < 2:
        return np.zeros(5)
    edf = _NoiseModel(tau[use], np.asarray(m, dtype=np.int64)[use], np.asarray(n_terms)[use], n_samples)
    x = tau[use][:, None] ** POWERS
    return _scoring(x, np.ones(5, dtype=bool), avar[use], edf, np.ones(len(use)), rtol=_QUICK_RTOL)[0]


def _coefficients(fits: list[CurveFit], confidence: float, windows: bool) -> list[Coefficient]:
    """The five Coefficients of curve fits (one curve: scalars; ``windows``: arrays over
    the windows, even of one). An identified term has its estimate and profile interval,
    or where that was not computed (a DADEV window) the sandwich interval A_n +- z se_n.
    A term not identifiable has value = lo = 0 and hi = its one-sided 95 % upper limit,
    or the upper end of its profile interval at ``confidence`` where that is higher (a
    level above 90 %): the test's outcome picks between an upper limit and a two-sided
    interval, and with a 95 % upper limit beside 95 % two-sided intervals a term near its
    detection limit is missed below in 5 % of the records and above in 2.5 % (92.5 %
    coverage for a Gaussian estimate; "flip-flopping", Feldman & Cousins 1998, Phys. Rev.
    D 57, 3873). QNB_1kHz_17min's B (validation/calibration.py, 1000 records): 92.9 %."""
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    a = np.array([f.a for f in fits])
    se = np.array([f.se for f in fits])
    ident = np.array([f.identifiable for f in fits]) & np.isfinite(a)
    lo_a = np.array([f.lo for f in fits])
    hi_a = np.array([f.hi for f in fits])
    upper = np.array([f.upper for f in fits])
    reach = np.fmax(upper, hi_a)  # an unidentified term's interval: 0 .. this (NaN hi_a: not computed)
    lo_a = np.where(np.isnan(lo_a), np.maximum(a - z * se, 0.0), lo_a)
    hi_a = np.where(np.isnan(hi_a), a + z * se, hi_a)
    conv = avar_terms_to_coefficients

    def kept(v):  # the coefficients of A_n, inf and NaN kept
        return np.where(np.isfinite(v), conv(np.where(np.isfinite(v), v, 0.0)), v)

    value = np.where(ident, conv(np.where(np.isfinite(a), a, 0.0)), np.where(np.isfinite(a), 0.0, np.nan))
    up = kept(upper)
    lo = np.where(ident, conv(np.where(np.isfinite(lo_a), lo_a, 0.0)), 0.0)
    hi = np.where(ident, conv(np.where(np.isfinite(hi_a), hi_a, 0.0)), kept(reach))
    hi = np.where(ident & np.isinf(hi_a), np.inf, hi)
    return [Coefficient(*(v[:, i] if windows else v[0, i].item() for v in (value, lo, hi, ident, up)))
            for i in range(5)]


def _worst_ratio(model_adev: np.ndarray, adev: np.ndarray, misfit: np.ndarray) -> np.ndarray:
    """Largest max(model/measured, measured/model) over usable, unflagged taus (last axis)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.abs(np.log(model_adev / adev))
    r = np.where(np.isfinite(r) & ~misfit, r, -np.inf).max(axis=-1)
    return np.where(np.isfinite(r), np.exp(r), np.nan)


def fit_noise(result: AdevResult | DadevResult, confidence: float = CONFIDENCE) -> NoiseFit:
    """Fit IEEE-952 Q (arcsec), N (deg/sqrt(h)), B (deg/h), K (deg/h/sqrt(h)), R (deg/h^2)
    to an AdevResult (scalar coefficients) or to every window of a DadevResult (arrays
    over windows: the coefficient time series). Intervals at ``confidence`` from the
    profile likelihood with every other term free (``fit_curve``); taus the five terms
    cannot describe are down-weighted, flagged in ``misfit`` and left out of
    ``worst_ratio``. Every coefficient also carries its one-sided 95 % upper limit
    ``upper`` (the ``hi`` of a term that is not identifiable). A DadevResult fit computes
    the profile only for the identification test and the upper limits of the terms not
    identifiable (NaN elsewhere); its identified terms get the sandwich interval A_n +-
    z se_n of the five-term fit (the windows need only what they print, at a third of
    the cost). An AdevResult fit is then checked against the measured ADEV
    (:func:`checked_against_adev`)."""
    avar = np.square(result.adev_dph)
    if isinstance(result, DadevResult):
        n = result.window_samples
        fits = [fit_curve(result.tau_s, avar[i], result.m, result.n_terms[i], n, confidence, "unidentified")
                for i in range(len(result))]
        misfit = np.array([f.misfit for f in fits], dtype=bool).reshape(result.adev_dph.shape)
    else:
        fits = [fit_curve(result.tau_s, avar, result.m, result.n_terms, result.n_samples, confidence, "all",
                          result.ramp_k)]
        misfit = fits[0].misfit
    shape = (len(fits), 5) if isinstance(result, DadevResult) else (5,)
    a = np.array([f.a for f in fits]).reshape(shape)
    se = np.array([f.se for f in fits]).reshape(shape)
    upper = np.array([f.upper for f in fits]).reshape(shape)
    q, n_, b, k, r = _coefficients(fits, confidence, isinstance(result, DadevResult))
    fit = NoiseFit(q, n_, b, k, r, avar_terms=a, avar_se=se, avar_upper=upper,
                   confidence=confidence, misfit=misfit, worst_ratio=np.nan, check_terms=fits[0].a_check)
    worst = _worst_ratio(fit.model_adev_dph(result.tau_s), result.adev_dph, misfit)
    if isinstance(result, DadevResult):
        return windows_checked_against_adev(replace(fit, worst_ratio=worst), result)
    return checked_against_adev(replace(fit, worst_ratio=float(worst)), result)


#: What the check against the measured ADEV does to a contradicted, identified term:
#: B, K, R are no longer identified (``termcheck``); Q keeps its value (renamed).
_DEMOTED = ("B_dph", "K_dphsh", "R_dphh")


def windows_checked_against_adev(fit: NoiseFit, result: DadevResult) -> NoiseFit:
    """The DADEV fit ``fit`` (arrays over the windows of ``result``) with each window's
    identified B, K and R checked against that window's ADEV as ``checked_against_adev``
    checks a whole curve: a contradicted one is not identifiable in that window (value =
    lo = 0, hi = upper = the lesser of the fit's upper limit and the ADEV's). Q keeps its
    value (its name is the whole curve's business); ``contradicted`` stays empty."""
    ident = {n: np.asarray(getattr(fit, n).identifiable, dtype=bool) for n in _DEMOTED}
    rows = np.flatnonzero(np.any([ident[n] for n in _DEMOTED], axis=0))
    if not len(rows):
        return fit
    cols = {n: {a: np.array(getattr(getattr(fit, n), a), dtype=float) for a in ("value", "lo", "hi", "upper")}
            for n in _DEMOTED}
    edf = np.broadcast_to(result.edf, result.adev_dph.shape)
    changed = False
    for i in rows:
        judged = tuple(n for n in _DEMOTED if ident[n][i])
        for c in contradictions(result.tau_s, result.adev_dph[i], _check_edf(fit.avar_terms[i], edf[i],
                                result.tau_s, result.m, result.n_terms[i], result.window_samples),
                                fit.avar_terms[i], judged):
            col = cols[c.name]
            up = _demoted_upper(float(col["upper"][i]), c)
            col["value"][i] = col["lo"][i] = 0.0
            col["hi"][i] = col["upper"][i] = up
            ident[c.name][i] = False
            changed = True
    if not changed:
        return fit
    checked = {n: Coefficient(cols[n]["value"], cols[n]["lo"], cols[n]["hi"], ident[n], cols[n]["upper"])
               for n in _DEMOTED}
    return replace(fit, **checked)  # type: ignore[arg-type]


def _demoted_upper(upper: float, c: TermContradiction) -> float:
    """The upper limit of a term ``c`` demotes: the lesser of the fit's ``upper`` (NaN:
    not computed) and the measured ADEV's bound ``c.limit``."""
    return min(upper, c.limit) if np.isfinite(upper) else c.limit


def _check_edf(a: np.ndarray, edf: np.ndarray, tau: np.ndarray, m: np.ndarray, n_terms: np.ndarray,
               n_samples: int) -> np.ndarray:
    """The EDF per tau the check against the measured ADEV uses: the lesser of the ADEV's
    and that of the noise the fit ``a`` describes. The ADEV's quick noise-type fit can take
    a filtered record for white noise (an EDF of 11,000 at 82 s where its flicker floor
    leaves ~30), and a check that overrides the fit must not be more confident than either."""
    full = np.maximum(n_samples - 2 * np.asarray(m) + 1, 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        edf_fit = mixture_edf_row(a, tau, m, n_samples) * n_terms / full
    return np.fmin(np.asarray(edf, dtype=float), edf_fit)


def checked_against_adev(fit: NoiseFit, result: AdevResult) -> NoiseFit:
    """``fit`` (of the curve ``result``) with the identified terms whose own ADEV exceeds
    the measured ADEV's upper bound (``termcheck.contradictions``, with each tau's EDF
    the lesser of the ADEV's and that of the noise the fit describes) listed in
    ``contradicted``; of them B, K and R not identifiable, with the upper limit the
    lesser of the fit's and the ADEV's (``TermContradiction.limit``)."""
    judged = tuple(n for n in ("Q_arcsec", *_DEMOTED) if bool(getattr(fit, n).identifiable))
    if not judged:
        return fit
    edf = _check_edf(fit.avar_terms, result.edf, result.tau_s, result.m, result.n_terms, result.n_samples)
    found = contradictions(result.tau_s, result.adev_dph, edf, fit.avar_terms, judged)
    if not found:
        return fit
    for c in found:
        if c.name in _DEMOTED:
            up = _demoted_upper(float(getattr(fit, c.name).upper), c)
            fit = replace(fit, **{c.name: Coefficient(0.0, 0.0, up, False, up)})  # type: ignore[arg-type]
    return replace(fit, contradicted=tuple(found))
