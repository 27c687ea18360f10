"""The analysis of one accelerometer of a run (``AccelAnalysis``): its aux channel
``accel_<name>_g`` (g) in micro-g through the gyros' streaming DAVAR and fit
(fogmon.davar.accel), on the samples its gyro axis's motion gate releases, with the
motion that gate found kept out of it too; and the tail for its whole-run ADEV.
"""
from __future__ import annotations

import re
import warnings

import numpy as np

from fogmon.davar.accel import AccelFit, fit_accel, to_ug
from fogmon.davar.result import DadevResult
from fogmon.errors import FogmonError, FogmonWarning
from fogmon.pipeline.axis import OVERALL_MAX_SAMPLES, _AuxFifo, _Tail
from fogmon.pipeline.config import TauSpec
from fogmon.sinks.base import AccelSummary

#: An accelerometer's aux channel: ``accel_<name>_g`` (g), <name> its axis (letters and digits).
ACCEL_CHANNEL = re.compile(r"accel_([A-Za-z0-9]+)_g")


def accel_channels(aux_names, wanted: tuple[str, ...] | None) -> dict[str, str]:
    """Accelerometer name -> aux channel of the ``accel_<name>_g`` channels among
    ``aux_names``, those named in ``wanted`` (None: all; (): none)."""
    found = {m.group(1): n for n in aux_names if (m := ACCEL_CHANNEL.fullmatch(n))}
    return {a: c for a, c in found.items() if wanted is None or a in wanted}


class AccelAnalysis:
    """Accelerometer ``name`` (aux channel ``channel``, g) of a run: its samples wait
    (``push``) until the gyro axis it follows releases the same samples from its motion
    gate (``analyse``: how many, and which of them the gate found in motion), then enter
    DAVAR in micro-g, invalid where the channel is NaN or the platform moved."""

    def __init__(self, name: str, channel: str, sample_rate_hz: float, window_s: float, hop_s: float,
                 taus: TauSpec, summary: AccelSummary) -> None:
        from fogmon.davar.streaming import StreamingDadev

        self.name, self.channel, self.summary, self.sample_rate_hz = name, channel, summary, sample_rate_hz
        self.engine = StreamingDadev(sample_rate_hz, window_s, taus=taus, hop_s=hop_s)
        self.tail = _Tail(OVERALL_MAX_SAMPLES)
        self._held = _AuxFifo()

    def push(self, aux: dict[str, np.ndarray], n: int) -> None:
        """The next ``n`` samples of a block (its aux channels; NaN where absent)."""
        a = aux.get(self.channel)
        self._held.push({"ug": to_ug(a) if a is not None else np.full(n, np.nan)}, n)

    def analyse(self, moving: np.ndarray) -> DadevResult:
        """The next len(``moving``) held samples into DAVAR (``moving``: those the gate
        kept out of the gyro's analysis); the windows they complete."""
        n = len(moving)
        ug = self._held.take(n).get("ug", np.zeros(0))
        valid = np.isfinite(ug)
        self.summary.n_invalid += int(n - np.count_nonzero(valid))
        kept_out = valid & moving
        self.summary.motion_samples += int(np.count_nonzero(kept_out))
        valid &= ~moving
        y = np.where(valid, ug, 0.0)
        self.tail.push(y, valid)
        return self.engine.push(y, valid)

    def fit(self, res: DadevResult) -> AccelFit:
        """The windows' IEEE Std 1293 fit."""
        self.summary.n_windows += len(res)
        return fit_accel(res)

    def overall(self, t_last_s: float, taus: TauSpec) -> None:
        """The whole-run ADEV (micro-g) and its fit (the latest OVERALL_MAX_SAMPLES samples,
        the last at ``t_last_s``) into the summary; nothing when the channel never had two
        valid samples in a row."""
        from fogmon.davar.batch import oadev

        del self.engine
        ug, valid, _ = self.tail.take()
        if len(ug) < 8 or not np.any(valid[1:] & valid[:-1]):
            return
        try:
            self.summary.overall = oadev(ug, self.sample_rate_hz, taus=taus, valid=valid)
        except FogmonError as e:
            warnings.warn(f"accelerometer {self.name}: no whole-run Allan deviation: {e.message}", FogmonWarning,
                          stacklevel=2)
            return
        self.summary.overall_first_s = t_last_s - (len(ug) - 1) / self.sample_rate_hz
        self.summary.overall_fit = fit_accel(self.summary.overall)
