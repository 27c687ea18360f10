"""Allan-deviation curves made by other tools (Stable32, MATLAB allanvar, allantools,
imu_utils, allan_variance_ros: fogmon.formats.curves reads their files) as fogmon
AdevResults, so that ``fit_noise`` gives their IEEE-952 fit with intervals.

The fit weighs each tau by the sampling statistics of an overlapping Allan variance over
a record of ``n_samples`` samples at ``sample_rate_hz`` with ``n_terms`` valid terms per tau
(fogmon.davar.fit). A curve carries at most part of that, so:
- ``sample_rate_hz``: given, else 1 / the first tau (the curve starts at the sample period);
  every tau must be a whole multiple m of the sample period to M_TOLERANCE (relative);
- ``n_terms`` (valid overlapping terms per tau): given, else every term of a gap-free
  record (n_samples - 2 m + 1); given, they must agree with the rate: gaps only ever
  remove more terms at a longer tau, so the terms missing from a gap-free record's,
  n_samples - 2 m + 1 - n_terms, are >= 0 and never fall as tau grows (a wrong rate
  breaks this);
- ``n_samples``: given, else from ``n_terms`` (max of n_terms + 2 m - 1), else assumed
  4 x the largest m (the curve ends at a quarter of the record, as octave grids do);
- ``edf`` (equivalent degrees of freedom per tau) when the other tool stated them: the
  fit's weights are scaled so that white rate noise gets exactly that EDF
  (n_terms = edf / EDF_white(m, n_samples) x (n_samples - 2 m + 1));
- ``estimator`` "non-overlapping" (allan_variance_ros): the EDF of white rate noise of the
  non-overlapping estimator over M = floor((n_samples - 1) / m) bins, 2 (M - 1)^2 / (3 M - 4)
  (its M - 1 differences of bin means are a moving average of correlation -1/2), is
  the stated EDF.
Every assumption made is returned as a sentence for the output."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from fogmon.davar.confidence import chi2_bounds, edf_effective, edf_full
from fogmon.davar.result import CONFIDENCE, AdevResult
from fogmon.errors import FogmonError


class CurveRowError(FogmonError):
    """A FogmonError about one tau of a curve: ``index`` (0-based, in the order given) and
    the ``column`` it is about ("tau_s", "n_terms"), so that a reader that knows the
    file's lines can name the line."""

    def __init__(self, message: str, index: int, column: str):
        super().__init__(message)
        self.index, self.column = index, column


#: a tau further than this (relative) from a whole multiple of the sample period is refused
#: (imu_utils's taus are multiples of the period measured from the stamps: 0.009999989 s at 100 Hz)
M_TOLERANCE = 1e-5
#: without n_terms or a record length, the record is assumed this many times the largest tau
ASSUMED_RECORD_TAUS = 4


def adev_from_curve(tau_s, adev_dph, *, sample_rate_hz: float | None = None, n_terms=None, edf=None,
                    n_samples: int | None = None, confidence: float = CONFIDENCE,
                    estimator: str = "overlapping") -> tuple[AdevResult, list[str]]:
    """(AdevResult, assumptions) for an Allan-deviation curve ``adev_dph`` (deg/h; any unit
    the fit reads alike, e.g. an accelerometer's micro-g) at ``tau_s`` (s, increasing),
    ready for ``fogmon.fit_noise``. Optional: ``sample_rate_hz`` (Hz), ``n_terms`` or
    ``edf`` per tau, ``n_samples`` of the record, ``estimator`` "overlapping" or
    "non-overlapping" (see the module docstring for what is assumed without them). The
    result's ``edf``, ``lo_dph`` and ``hi_dph`` assume white rate noise until
    ``with_fit_intervals`` replaces them with those of the fitted model. A bad argument is
    a FogmonError."""
    if estimator not in ("overlapping", "non-overlapping"):
        raise ValueError(f"adev_from_curve: estimator must be overlapping or non-overlapping, got {estimator!r}")
    tau, adev = _curve_arrays(tau_s, adev_dph)
    said: list[str] = []
    rate_given = sample_rate_hz is not None
    if sample_rate_hz is None:
        sample_rate_hz = 1.0 / float(tau[0])
        said.append(f"sample rate {sample_rate_hz:g} Hz (1 / the first tau; `sample_rate_hz` sets it)")
    m = _averaging_factors(tau, sample_rate_hz)
    n_terms = _positive("n_terms", n_terms, 1.0, "whole numbers >= 1")
    edf = _positive("edf", edf, 0.0, "finite and > 0", strict=True)
    n_samples = _record_samples(tau, m, sample_rate_hz, n_terms, n_samples, said)
    full = (n_samples - 2 * m + 1).astype(np.float64)
    white = edf_full(0, m, n_samples)
    if edf is None and estimator == "non-overlapping":
        bins = (n_samples - 1) // m
        edf = nonoverlapping_white_edf(bins)
        said.append("non-overlapping estimator: each tau weighed by the EDF of white rate noise over its "
                    "floor((N - 1) / m) bins, 2 (M - 1)^2 / (3 M - 4) (the other noise types scaled alike)")
    if edf is not None:
        terms = edf / white * full
        if n_terms is None and estimator == "overlapping":
            said.append("the stated EDF weighs each tau (exact for white rate noise, scaled alike for the others)")
    elif n_terms is not None:
        _check_terms(tau, m, n_terms, full, n_samples, sample_rate_hz, rate_given)
        terms = n_terms
    else:
        terms = full
        said.append("fully overlapping estimator, no gaps (an n_terms or edf column states them)")
    nu = edf if edf is not None else edf_effective(white, m, n_samples, terms)
    lo, hi = chi2_bounds(adev, nu, confidence)
    return AdevResult(tau, m, adev, lo, hi, nu, terms, float(sample_rate_hz), n_samples,
                      confidence), said


def nonoverlapping_white_edf(bins) -> np.ndarray:
    """EDF of the non-overlapping Allan variance of white rate noise over ``bins`` bins
    (>= 2): 2 (M - 1)^2 / (3 M - 4)."""
    b = np.asarray(bins, dtype=np.float64)
    return 2.0 * (b - 1.0) ** 2 / (3.0 * b - 4.0)


def _check_terms(tau, m, n_terms, full, n_samples: int, sample_rate_hz: float, rate_given: bool) -> None:
    """FogmonError unless the terms missing from a gap-free record's (``full`` -
    ``n_terms``) are >= 0 and never fall as tau grows (gaps remove more terms at longer
    taus): a sample rate that makes the averaging factors ``m`` wrong breaks this."""
    missing = full - n_terms
    rate = (f"`sample_rate_hz` {sample_rate_hz:.10g} Hz" if rate_given else
            f"the sample rate {sample_rate_hz:.10g} Hz (assumed: 1 / the first tau)")
    fits = ""
    if len(tau) > 1 and n_terms[0] > n_terms[1]:   # gap-free: n_terms + 2 m constant, so this is the rate
        fits = (f"; the n_terms of the first two taus fit {(n_terms[0] - n_terms[1]) / (2 * (tau[1] - tau[0])):.10g} "
                f"Hz (2 terms fewer per sample period)")
    if np.any(missing < 0):
        i = int(np.argmax(missing < 0))
        raise CurveRowError(f"n_terms {int(n_terms[i])} at tau {tau[i]:.10g} s is {int(-missing[i])} more than the "
                            f"{int(full[i])} overlapping terms (N - 2 m + 1, m = {int(m[i])}) a record of "
                            f"{n_samples} samples has: the record is longer, or {rate} is wrong{fits}", i, "n_terms")
    fell = np.flatnonzero(np.diff(missing) < 0)
    if len(fell):
        i = int(fell[0])
        raise CurveRowError(f"{rate} contradicts n_terms: at tau {tau[i]:.10g} s (m = {int(m[i])}) "
                            f"{int(missing[i])} terms are missing from a gap-free record's, at {tau[i + 1]:.10g} s "
                            f"(m = {int(m[i + 1])}) only {int(missing[i + 1])}, and gaps can only remove more terms "
                            f"at a longer tau{fits}", i + 1, "n_terms")


def _curve_arrays(tau_s, adev_dph) -> tuple[np.ndarray, np.ndarray]:
    """tau (s) and ADEV (deg/h) as float arrays, checked: equal length >= 2, tau finite,
    > 0 and increasing, ADEV finite and > 0."""
    tau = np.asarray(tau_s, dtype=np.float64)
    adev = np.asarray(adev_dph, dtype=np.float64)
    if tau.ndim != 1 or tau.shape != adev.shape or len(tau) < 2:
        raise FogmonError("a curve needs tau_s and adev_dph of equal length, at least 2 points")
    if not (np.all(np.isfinite(tau)) and tau[0] > 0 and np.all(np.diff(tau) > 0)):
        raise FogmonError("tau_s must be finite, > 0 and strictly increasing")
    if not (np.all(np.isfinite(adev)) and np.all(adev > 0)):
        raise FogmonError("adev_dph must be finite and > 0")
    return tau, adev


def _averaging_factors(tau: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """m = tau x sample rate, which must be whole numbers >= 1 (within M_TOLERANCE)."""
    k = tau * sample_rate_hz
    m = np.rint(k).astype(np.int64)
    off = np.abs(k - m) / np.maximum(k, 1.0)
    if m[0] < 1 or off.max() > M_TOLERANCE:
        i = int(np.argmax(off)) if m[0] >= 1 else 0
        raise CurveRowError(f"tau_s {tau[i]:.10g} s is not a whole multiple of the sample period "
                            f"{1 / sample_rate_hz:.10g} s ({k[i]:.7g} periods, more than {M_TOLERANCE:g} from a whole "
                            f"number; give the record's sample rate with `sample_rate_hz`)", i, "tau_s")
    return m


def _positive(name: str, values, least: float, need: str, strict: bool = False) -> np.ndarray | None:
    """``values`` as a float array, each finite and >= ``least`` (> with ``strict``); None stays None."""
    if values is None:
        return None
    a = np.asarray(values, dtype=np.float64)
    ok = np.all(np.isfinite(a)) and (np.all(a > least) if strict else np.all(a >= least))
    if not ok:
        raise FogmonError(f"{name} must be {need}")
    return a


def _record_samples(tau, m, sample_rate_hz, n_terms, n_samples, said: list[str]) -> int:
    """The record length in samples: given, else from ``n_terms``, else assumed
    ASSUMED_RECORD_TAUS x the largest m (said); it must hold two of the largest tau."""
    if n_samples is None:
        if n_terms is not None:
            n_samples = int(np.max(n_terms + 2 * m - 1))
        else:
            n_samples = int(ASSUMED_RECORD_TAUS * m[-1])
            said.append(f"record of {n_samples} samples = {n_samples / sample_rate_hz:g} s ({ASSUMED_RECORD_TAUS} x "
                        f"the largest tau; an n_terms column or `n_samples` sets it)")
    n_samples = int(n_samples)
    if 2 * m[-1] > n_samples:
        raise CurveRowError(f"the largest tau {tau[-1]:.10g} s needs a record of at least "
                            f"{2 * m[-1] / sample_rate_hz:.10g} s ({2 * m[-1]} samples), not "
                            f"{n_samples / sample_rate_hz:.10g} s ({n_samples} samples)", len(tau) - 1, "tau_s")
    return n_samples


def with_fit_intervals(result: AdevResult, fit, edf_stated: bool) -> AdevResult:
    """``result`` with EDF and intervals for the noise mixture the fitted model predicts
    at each tau (as replay's summary shows them), unless the EDF was stated."""
    if edf_stated or not np.all(np.isfinite(fit.avar_terms)):
        return result
    from fogmon.davar.fit import mixture_edf_row
    nu = edf_effective(mixture_edf_row(fit.avar_terms, result.tau_s, result.m, result.n_samples), result.m,
                       result.n_samples, result.n_terms)
    lo, hi = chi2_bounds(result.adev_dph, nu, result.confidence)
    return replace(result, edf=nu, lo_dph=lo, hi_dph=hi)
