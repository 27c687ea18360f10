"""The whole-record fit of a record: the one place that turns a rate record into its
overall Allan deviation and IEEE-952 coefficients, so that every command that states a
record's coefficients (``fogmon replay``/``monitor``/``batch`` at the end of a run,
``fogmon explain``'s report) states the same numbers for the same samples: the same
taus (the run's grid, "octave" by default), the same fit (``fit_noise``: robust Fisher
scoring on the octave subset, profile intervals) and the same check of every term
against the measured ADEV (``termcheck``)."""
from __future__ import annotations

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
    return adev, fit_noise(adev, confidence)
