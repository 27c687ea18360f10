"""Allan-deviation curves made by other tools (Stable32, MATLAB allanvar, allantools...) as
fogmon AdevResults, so that ``fit_noise`` gives their IEEE-952 fit with intervals.

The fit weighs each tau by the sampling statistics of an overlapping Allan variance over
a record of ``n_samples`` samples at ``sample_rate_hz`` with ``n_terms`` valid terms per tau
(fogmon.davar.fit). A curve carries at most part of that, so:
- ``sample_rate_hz``: given, else 1 / the first tau (the curve starts at the sample period);
- ``n_terms`` (valid overlapping terms per tau): given, else every term of a gap-free
  record (n_samples - 2 m + 1);
- ``n_samples``: given, else from ``n_terms`` (max of n_terms + 2 m - 1), else assumed
  4 x the largest m (the curve ends at a quarter of the record, as octave grids do);
- ``edf`` (equivalent degrees of freedom per tau) when the other tool stated them: the
  fit's weights are scaled so that white rate noise gets exactly that EDF
  (n_terms = edf / EDF_white(m, n_samples) x (n_samples - 2 m + 1)).
Every assumption made is returned as a sentence for the output."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from fogmon.davar.confidence import chi2_bounds, edf_effective, edf_full
from fogmon.davar.result import CONFIDENCE, AdevResult
from fogmon.errors import FogmonError

#: a tau further than this (relative) from a whole multiple of the sample period is refused
M_TOLERANCE = 1e-6
#: without n_terms or a record length, the record is assumed this many times the largest tau
ASSUMED_RECORD_TAUS = 4


def adev_from_curve(tau_s, adev_dph, *, sample_rate_hz: float | None = None, n_terms=None, edf=None,
                    n_samples: int | None = None, confidence: float = CONFIDENCE) -> tuple[AdevResult, list[str]]:
    """(AdevResult, assumptions) for an Allan-deviation curve ``adev_dph`` (deg/h) at
    ``tau_s`` (s, increasing), ready for ``fogmon.fit_noise``. Optional: ``sample_rate_hz``
    (Hz), ``n_terms`` or ``edf`` per tau, ``n_samples`` of the record (see the module
    docstring for what is assumed without them). The result's ``edf``, ``lo_dph`` and
    ``hi_dph`` assume white rate noise until ``with_fit_intervals`` replaces them with
    those of the fitted model. A bad argument is a FogmonError."""
    tau, adev = _curve_arrays(tau_s, adev_dph)
    said: list[str] = []
    if sample_rate_hz is None:
        sample_rate_hz = 1.0 / float(tau[0])
        said.append(f"sample rate {sample_rate_hz:g} Hz (1 / the first tau; `sample_rate_hz` sets it)")
    m = _averaging_factors(tau, sample_rate_hz)
    n_terms = _positive("n_terms", n_terms, 1.0, "whole numbers >= 1")
    edf = _positive("edf", edf, 0.0, "finite and > 0", strict=True)
    n_samples = _record_samples(tau, m, sample_rate_hz, n_terms, n_samples, said)
    full = (n_samples - 2 * m + 1).astype(np.float64)
    white = edf_full(0, m, n_samples)
    if edf is not None:
        terms = edf / white * full
        if n_terms is None:
            said.append("the stated EDF weighs each tau (exact for white rate noise, scaled alike for the others)")
    elif n_terms is not None:
        if np.any(n_terms > full):
            i = int(np.argmax(n_terms > full))
            raise FogmonError(f"n_terms {n_terms[i]:g} at tau {tau[i]:g} s is more than the {full[i]:g} overlapping "
                              f"terms a record of {n_samples} samples has")
        terms = n_terms
    else:
        terms = full
        said.append("fully overlapping estimator, no gaps (an n_terms or edf column states them)")
    nu = edf if edf is not None else edf_effective(white, m, n_samples, terms)
    lo, hi = chi2_bounds(adev, nu, confidence)
    return AdevResult(tau, m, adev, lo, hi, nu, terms, float(sample_rate_hz), n_samples,
                      confidence), said


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
        raise FogmonError(f"tau_s {tau[i]:g} s is not a whole multiple of the sample period {1 / sample_rate_hz:g} s "
                          f"(give the record's sample rate with `sample_rate_hz`)")
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
        raise FogmonError(f"the largest tau {tau[-1]:g} s needs a record of at least {2 * m[-1] / sample_rate_hz:g} s "
                          f"({2 * m[-1]} samples), not {n_samples / sample_rate_hz:g} s")
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


def read_curve_csv(path: str) -> tuple[dict[str, np.ndarray], list[int]]:
    """Columns of an ADEV curve CSV (``tau_s,adev_dph`` and optionally ``edf`` or
    ``n_terms``; ``#`` comment lines; BOM and CRLF accepted) as arrays, and the file line
    of each row. A bad file is a one-line FogmonError naming file, line and column."""
    cols: list[str] | None = None
    rows: list[list[float]] = []
    line_no: list[int] = []
    for i, raw in enumerate(_text_lines(path), 1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        if cols is None:
            cols = _curve_header(cells, path, i)
            continue
        row = _curve_row(cols, cells, path, i)
        t = cols.index("tau_s")
        if rows and row[t] <= rows[-1][t]:
            raise FogmonError(f"{path}: line {i}, column tau_s: {row[t]:g} is not above the "
                              f"previous tau ({rows[-1][t]:g}): taus must increase")
        rows.append(row)
        line_no.append(i)
    if cols is None or len(rows) < 2:
        raise FogmonError(f"{path}: needs a header (tau_s,adev_dph[,edf|n_terms]) and at least 2 rows")
    a = np.array(rows, dtype=np.float64)
    return {c: a[:, j] for j, c in enumerate(cols)}, line_no


def _text_lines(path: str) -> list[str]:
    """The lines of a UTF-8 text file (BOM and CRLF accepted), or a one-line FogmonError."""
    try:
        with open(path, encoding="utf-8-sig", newline=None) as fh:
            return fh.read().splitlines()
    except FileNotFoundError:
        raise FogmonError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise FogmonError(f"{path}: is a folder, not a curve CSV") from None
    except (OSError, UnicodeDecodeError) as e:
        raise FogmonError(f"{path}: cannot read: {getattr(e, 'strerror', None) or e}") from None


def _curve_header(cols: list[str], path: str, i: int) -> list[str]:
    """The header's columns, checked: tau_s and adev_dph, optionally edf or n_terms."""
    for need in ("tau_s", "adev_dph"):
        if need not in cols:
            raise FogmonError(f"{path}: line {i}: header has no column {need} (columns: tau_s,adev_dph "
                              f"and optionally edf or n_terms)")
    unknown = [c for c in cols if c not in ("tau_s", "adev_dph", "edf", "n_terms")]
    if unknown or len(set(cols)) != len(cols):
        raise FogmonError(f"{path}: line {i}: column {(unknown or cols)[0]!r}: unknown or repeated (columns: "
                          f"tau_s, adev_dph, edf, n_terms)")
    return cols


def _curve_row(cols: list[str], cells: list[str], path: str, i: int) -> list[float]:
    """One data row's values, checked cell by cell (n_terms whole >= 1, the others > 0)."""
    if len(cells) != len(cols):
        raise FogmonError(f"{path}: line {i}: {len(cells)} cells, the header has {len(cols)}")
    row = []
    for c, v in zip(cols, cells, strict=True):
        try:
            x = float(v)
        except ValueError:
            raise FogmonError(f"{path}: line {i}, column {c}: not a number: {v[:40]!r}") from None
        bad = (not np.isfinite(x) or x <= 0 if c in ("tau_s", "adev_dph", "edf") else
               not np.isfinite(x) or x < 1 or not float(x).is_integer())
        if bad:
            need = "a whole number >= 1" if c == "n_terms" else "a finite number > 0"
            raise FogmonError(f"{path}: line {i}, column {c}: must be {need}, got {v[:40]!r}")
        row.append(x)
    return row
