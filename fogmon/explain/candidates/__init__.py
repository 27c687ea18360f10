"""Candidate physics (effect kinds of docs/formats.md), each fitted to the current
residual and scored by a likelihood-ratio statistic ``gain`` with ``k`` free
parameters (scanned nonlinear ones included), so that forward selection can compare
them by BIC: accept when gain - k ln(n) > 0 and a held-out check passes.

One module per family (``base``: what they share):

- ``mean``: thermal_drift, periodic, bias_step, rate_ramp, scale_factor, warm_up -
  linear in their amplitude-type coefficients, fitted by Whittle GLS with the
  calibrated noise PSD; nonlinear parameters by scans.
- ``spikes``: glitches and outliers, the two descriptions of the robust spike test.
- ``spectral``: markov and bandwidth change the noise PSD - Whittle likelihood of the
  residual's binned periodogram under the model PSD with and without the term.
- ``white_level``: vibration_noise and temperature_noise change the white-noise level
  over time - per-segment white level regressed on the segment mean of vib_g / temp_c.
- ``lines``: vibration_lines, narrowband random vibration.
- ``coefficients``: noise, the model's own IEEE-952 coefficients corrected.
- ``aux_response``: a law outside the catalogue, a sparse sum of terms following the aux
  channels and the other axes' rates (forward stepwise on the Whittle GLS).

``CANDIDATES`` maps each kind to its candidate function, in the order explain fits
them (ties in BIC gain keep this order).
"""
from __future__ import annotations

from collections.abc import Callable

from fogmon.explain.candidates.aux_response import aux_response
from fogmon.explain.candidates.base import Candidate, Context
from fogmon.explain.candidates.coefficients import noise
from fogmon.explain.candidates.lines import vibration_lines
from fogmon.explain.candidates.mean import bias_step, periodic, rate_ramp, scale_factor, thermal_drift, warm_up
from fogmon.explain.candidates.spectral import bandwidth, markov
from fogmon.explain.candidates.spikes import glitches, outliers
from fogmon.explain.candidates.white_level import temperature_noise, vibration_noise

#: kind -> the function fitting it to a context (None: not applicable to this residual)
CANDIDATES: dict[str, Callable[[Context], Candidate | None]] = {
    "periodic": periodic,
    "bias_step": bias_step,
    "rate_ramp": rate_ramp,
    "warm_up": warm_up,
    "scale_factor": scale_factor,
    "thermal_drift": thermal_drift,
    "glitches": glitches,
    "outliers": outliers,
    "markov": markov,
    "bandwidth": bandwidth,
    "vibration_noise": vibration_noise,
    "temperature_noise": temperature_noise,
    "vibration_lines": vibration_lines,
    "noise": noise,
    "aux_response": aux_response,
}

__all__ = ["CANDIDATES", "Candidate", "Context"]
