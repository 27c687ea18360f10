"""The papers' methods applied to the live rate, block by block, before DAVAR: thermal
drift correction (``thermal``), outlier rejection (``outlier_k``) and a
Kalman-denoised channel (``kalman_n_k``). Each is causal (no future samples).

What each adds to the block's aux channels (archived and drawn beside the raw rate):
``rate_corrected_dph`` and ``thermal_drift_dph`` (deg/h) with a thermal calibration,
``rate_kalman_dph`` (deg/h) with the Kalman channel. Rejected outliers become invalid
for the analysis (the archive keeps the raw sample) and are reported as ``outlier``
events, one per block that has any, and counted."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fogmon.block import Event
from fogmon.errors import FogmonError
from fogmon.sim.model import Effect

if TYPE_CHECKING:
    from fogmon.methods.denoise import StaticKalmanStream
    from fogmon.methods.live_outliers import OutlierRejector
    from fogmon.methods.live_thermal import LiveThermalCorrection

CORRECTED = "rate_corrected_dph"
DRIFT = "thermal_drift_dph"
KALMAN = "rate_kalman_dph"


@dataclass(frozen=True)
class LiveMethods:
    """Which methods run: ``thermal`` the calibrated ``thermal_drift`` effect (None: no
    correction), ``outlier_k`` the rejection threshold in sigmas of one sample (None: no
    rejection), ``kalman_n_k`` (N deg/sqrt(h), K deg/h/sqrt(h)) of the static Kalman
    channel (None: none)."""

    thermal: Effect | None = None
    outlier_k: float | None = None
    kalman_n_k: tuple[float, float] | None = None

    @property
    def any(self) -> bool:
        return self.thermal is not None or self.outlier_k is not None or self.kalman_n_k is not None


@dataclass(frozen=True)
class Conditioned:
    """One block after the methods: the rate to analyse (deg/h) and its valid flags,
    the channels to add to the block, the events."""

    rate_dph: np.ndarray
    valid: np.ndarray
    channels: dict[str, np.ndarray]
    events: list[Event]


class Conditioner:
    """Runs the chosen methods on a stream of blocks (recording time s, rate deg/h)."""

    def __init__(self, methods: LiveMethods, sample_rate_hz: float) -> None:
        # a method's module is imported only when it runs: they pull in scipy.signal,
        # scipy.linalg and scipy.ndimage, a second of start-up for a run without them
        self.thermal: LiveThermalCorrection | None = None
        self.rejector: OutlierRejector | None = None
        self.kalman: StaticKalmanStream | None = None
        if methods.thermal is not None:
            from fogmon.methods.live_thermal import LiveThermalCorrection
            self.thermal = LiveThermalCorrection(methods.thermal)
        if methods.outlier_k is not None:
            from fogmon.methods.live_outliers import OutlierRejector
            self.rejector = OutlierRejector(methods.outlier_k)
        if methods.kalman_n_k is not None:
            from fogmon.methods.denoise import StaticKalmanStream
            self.kalman = StaticKalmanStream(sample_rate_hz, *methods.kalman_n_k)
        #: samples without a temperature, so without a thermal correction (invalid for the analysis)
        self.no_temperature = 0

    @property
    def channels(self) -> tuple[str, ...]:
        """Names of the aux channels ``push`` adds."""
        return ((CORRECTED, DRIFT) if self.thermal else ()) + ((KALMAN,) if self.kalman else ())

    def check(self, aux_names: tuple[str, ...], source: str) -> None:
        """FogmonError when the source lacks what a method needs (temp_c for the thermal
        correction)."""
        if self.thermal is not None and "temp_c" not in aux_names:
            raise FogmonError(f"`thermal`: {source} has no temp_c channel (deg C); the thermal correction "
                              f"needs the sensor temperature")

    def push(self, t_s: np.ndarray, rate_dph: np.ndarray, valid: np.ndarray,
             aux: Mapping[str, np.ndarray]) -> Conditioned:
        y, ok = rate_dph, valid
        channels: dict[str, np.ndarray] = {}
        events: list[Event] = []
        if self.thermal is not None:
            c = self.thermal.push(t_s, rate_dph, aux["temp_c"])
            y, ok = c.rate_dph, valid & ~c.unknown
            self.no_temperature += int(np.count_nonzero(valid & c.unknown))
            channels[CORRECTED], channels[DRIFT] = c.rate_dph, c.drift_dph
        if self.rejector is not None:
            out = self.rejector.push(y, ok)
            if out.any():
                idx = np.flatnonzero(out)
                dev = np.abs(y[idx])
                events.append(Event(float(t_s[idx[0]]), "outlier",
                                    f"{len(idx)} outlier(s) rejected from t = {t_s[idx[0]]:.3f} s (largest "
                                    f"|rate| {dev.max():.4g} deg/h; beyond {self.rejector.k:g} sigma of one sample "
                                    f"from the level predicted by the samples before)"))
                ok = ok & ~out
        if self.kalman is not None:
            channels[KALMAN] = self.kalman.push(np.where(ok, y, np.nan))
        return Conditioned(y, ok, channels, events)
