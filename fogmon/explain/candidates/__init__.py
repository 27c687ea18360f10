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

``CANDIDATES`` maps each kind to its candidate function, in the order explain fits
them (ties in BIC gain keep this order).
"""
from __future__ import annotations

from collections.abc import Callable

from fogmon.explain.candidates import coefficients, lines, mean, spectral, spikes, white_level
from fogmon.explain.candidates.base import Candidate, Context

#: kind -> the function fitting it to a context (None: not applicable to this residual)
CANDIDATES: dict[str, Callable[[Context], Candidate | None]] = {
    "periodic": mean.periodic,
    "bias_step": mean.bias_step,
    "rate_ramp": mean.rate_ramp,
    "warm_up": mean.warm_up,
    "scale_factor": mean.scale_factor,
    "thermal_drift": mean.thermal_drift,
    "glitches": spikes.glitches,
    "outliers": spikes.outliers,
    "markov": spectral.markov,
    "bandwidth": spectral.bandwidth,
    "vibration_noise": white_level.vibration_noise,
    "temperature_noise": white_level.temperature_noise,
    "vibration_lines": lines.vibration_lines,
    "noise": coefficients.noise,
}

__all__ = ["CANDIDATES", "Candidate", "Context"]
