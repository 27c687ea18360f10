"""The whole-record fit of a record: the one place that turns a rate record into its
overall Allan deviation and IEEE-952 coefficients, so that every command that states a
record's coefficients (``fogmon replay``/``monitor``/``batch`` at the end of a run,
``fogmon explain``'s report) states the same numbers for the same samples: the same
taus (the run's grid, "octave" by default), the same fit (``fit_noise``: robust Fisher
scoring on the octave subset, profile intervals) and the same check of every term
against the measured ADEV (``termcheck``)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from fogmon.davar.fit import NoiseFit
from fogmon.davar.result import CONFIDENCE, AdevResult

#: The taus of the whole-record fit unless a run asks for others.
RECORD_TAUS = "octave"


def whole_record_fit(rate_dph: np.ndarray, valid: np.ndarray | None, sample_rate_hz: float, taus=RECORD_TAUS,
                     confidence: float = CONFIDENCE) -> tuple[AdevResult, NoiseFit]:
    """(overall ADEV, IEEE-952 fit) of the rate ``rate_dph`` (deg/h) at ``sample_rate_hz``
    (Hz), the samples not ``valid`` (and NaN) left out: ``oadev`` on ``taus``, then
    ``fit_noise`` (which checks each term against that ADEV) at ``confidence``."""
    from fogmon.davar.batch import oadev
    from fogmon.davar.fit import fit_noise

    adev = oadev(rate_dph, sample_rate_hz, taus=taus, valid=valid, confidence=confidence)
    return adev, quantized_output(fit_noise(adev, confidence), rate_dph, valid, sample_rate_hz)


def quantized_output(fit: NoiseFit, rate_dph: np.ndarray, valid: np.ndarray | None, sample_rate_hz: float) -> NoiseFit:
    """``fit`` without its Q contradiction (``termcheck``: "white angle noise, not
    quantization", "an output quantizer is < X") when the samples lie on a lattice
    (``lattice_step_dph``) whose angle count q (arcsec: the step times the sample interval)
    makes a white quantizer, Q = q / sqrt(12), larger than that bound: the output is
    quantized, and its quantization error is not white in angle (the angle moves less than
    a count per sample, so consecutive errors correlate and the 1/tau slope does not reach
    the shortest taus), so neither statement holds; ``quantized_count_arcsec`` says so.
    A 2-arcsec counter at 100 Hz beside N 0.01 deg/sqrt(h) and B 0.1 deg/h (Q 0.577
    arcsec) was printed "white angle noise, not quantization ... an output quantizer is
    < 0.2066 arcsec"."""
    q = next((c for c in fit.contradicted if c.name == "Q_arcsec"), None)
    if q is None:
        return fit
    count = lattice_step_dph(rate_dph, valid) / sample_rate_hz
    if not count / np.sqrt(12.0) > q.limit:
        return fit
    return replace(fit, contradicted=tuple(c for c in fit.contradicted if c is not q), quantized_count_arcsec=count)


def lattice_step_dph(rate_dph: np.ndarray, valid: np.ndarray | None = None) -> float:
    """The step (deg/h) of the lattice the valid finite samples lie on (a counter's
    output: every value an integer multiple of the least difference between distinct
    values, within 1e-3 of it), NaN when they do not or hold fewer than 3 distinct values
    or more than a quarter as many as samples (a continuous output)."""
    y = np.asarray(rate_dph, dtype=np.float64)
    ok = np.isfinite(y) if valid is None else np.asarray(valid, dtype=bool) & np.isfinite(y)
    u = np.unique(y[ok])
    if len(u) < 3 or len(u) > np.count_nonzero(ok) // 4:
        return float("nan")
    step = float(np.min(np.diff(u)))
    k = (u - u[0]) / step
    return step if float(np.max(np.abs(k - np.round(k)))) <= 1e-3 else float("nan")
