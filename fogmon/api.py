"""The batch Allan deviations of the public API (``fogmon.oadev``, ``fogmon.dadev``): those
of fogmon.davar.batch behind the platform-motion gate that `fogmon replay` and `fogmon
monitor` apply (fogmon.motion, docs/motion.md), so that the API and the CLI give the same
numbers for the same record. ``exclude_motion=True`` (the default, as the CLI's) leaves
out the samples the gate judges platform motion and says how many in a FogmonWarning;
``exclude_motion=False`` analyses every sample, as `--keep-motion` does.
"""
from __future__ import annotations

import warnings

import numpy as np

from fogmon.davar import batch
from fogmon.davar.result import CONFIDENCE, AdevResult, DadevResult
from fogmon.errors import FogmonWarning


def oadev(rate_dph, sample_rate_hz: float, taus="octave", valid=None, confidence: float = CONFIDENCE,
          alpha=None, exclude_motion: bool = True) -> AdevResult:
    """fogmon.davar.batch.oadev of the samples outside platform motion (all with
    ``exclude_motion`` False)."""
    valid = _gate(rate_dph, sample_rate_hz, valid) if exclude_motion else valid
    return batch.oadev(rate_dph, sample_rate_hz, taus, valid, confidence, alpha)


def dadev(rate_dph, sample_rate_hz: float, window_s: float, hop_s: float | None = None, taus="octave",
          valid=None, confidence: float = CONFIDENCE, t0_s: float = 0.0, alpha=None,
          exclude_motion: bool = True) -> DadevResult:
    """fogmon.davar.batch.dadev of the samples outside platform motion (all with
    ``exclude_motion`` False)."""
    valid = _gate(rate_dph, sample_rate_hz, valid) if exclude_motion else valid
    return batch.dadev(rate_dph, sample_rate_hz, window_s, hop_s, taus, valid, confidence, t0_s, alpha)


oadev.__doc__ = f"{oadev.__doc__}\n\n{batch.oadev.__doc__}"
dadev.__doc__ = f"{dadev.__doc__}\n\n{batch.dadev.__doc__}"


def _gate(rate_dph, sample_rate_hz: float, valid) -> np.ndarray | None:
    """``valid`` with platform motion made invalid; a FogmonWarning when any was."""
    from fogmon.motion_gate import gate_record

    y = np.asarray(rate_dph, dtype=np.float64)
    if y.ndim != 1 or (valid is not None and np.shape(valid) != y.shape):
        return valid                         # batch's own check says what is wrong
    gated = gate_record(y, sample_rate_hz, valid)
    if gated.spans:
        spans = ", ".join(f"{m.t_start_s:.2f}..{m.t_end_s:.2f} s" for m in gated.spans[:3])
        more = f" and {len(gated.spans) - 3} more" if len(gated.spans) > 3 else ""
        warnings.warn(f"platform motion: {len(gated.spans)} span(s) ({spans}{more} from the first sample), "
                      f"{gated.samples_excluded} samples ({100.0 * gated.samples_excluded / max(len(y), 1):.1f} %) "
                      f"kept out, as fogmon replay does (`exclude_motion` False analyses them; docs/motion.md)",
                      FogmonWarning, stacklevel=3)
    return gated.valid
