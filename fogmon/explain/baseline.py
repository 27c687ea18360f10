"""A stationary baseline model from the recording itself, for `fogmon explain` without
``--model``: bias = mean of (rate - 3600 rot_dps) in deg/h, IEEE-952 Q, N, B, K, R from
the whole-record overlapping ADEV (octave taus, the DAVAR engine) by non-negative least
squares on the *relative* Allan-variance error, equal weight per octave wherever the
EDF exceeds 50 (less at the longest taus).

Why not the statistically weighted fit (``fogmon.davar.fit_noise``)? A baseline must
follow the recording's ADEV curve at every tau so that what is left is what is *not*
stationary; the EDF-weighted fit lets the many-EDF short taus decide and, on real data
whose short taus are dominated by platform motion (the PSINS ring-laser record),
returns a flat flicker model that misses the long taus by 20x. No effects: explaining
against this model asks "what in this recording is not stationary IEEE-952 noise?"."""
from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from fogmon.davar.batch import oadev
from fogmon.davar.theory import POWERS, avar_terms_to_coefficients
from fogmon.errors import FogmonError
from fogmon.recording import Recording
from fogmon.sim.model import Noise, SensorModel, validate_model


def curve_noise_fit(tau_s: np.ndarray, adev_dph: np.ndarray, edf: np.ndarray | None = None,
                    edf_cap: float = 50.0) -> dict[str, float]:
    """IEEE-952 coefficients (Q arcsec, N deg/sqrt(h), B deg/h, K deg/h/sqrt(h), R deg/h^2)
    minimizing sum_i w_i (model_avar_i / avar_i - 1)^2 over the taus, all A_n >= 0, with
    w_i = min(edf_i, edf_cap) / edf_cap: equal weight wherever the point is well
    determined, less at the few-EDF longest taus."""
    ok = np.isfinite(adev_dph) & (adev_dph > 0)
    tau, av = np.asarray(tau_s)[ok], np.asarray(adev_dph)[ok] ** 2
    w = np.ones(len(tau)) if edf is None else np.sqrt(np.minimum(np.asarray(edf)[ok], edf_cap) / edf_cap)
    X = tau[:, None] ** POWERS[None, :] / av[:, None] * w[:, None]
    scale = np.max(np.abs(X), axis=0)
    scale[scale == 0] = 1.0
    a, _ = nnls(X / scale, w)
    coef = avar_terms_to_coefficients(a / scale)
    return dict(zip(("Q_arcsec", "N_dpsh", "B_dph", "K_dphsh", "R_dphh"), map(float, coef)))


def baseline_model(rec: Recording) -> SensorModel:
    """Stationary IEEE-952 model (no effects) fitted to ``rec``."""
    blk = rec.to_block()
    y = blk.error_rate_dph
    ok = blk.valid & np.isfinite(y)
    if ok.sum() < 64:
        raise FogmonError(f"{rec.name}: too few valid samples ({int(ok.sum())}) to fit a baseline model")
    res = oadev(y, rec.sample_rate_hz, taus="octave", valid=ok, alpha=0)
    vals = curve_noise_fit(res.tau_s, res.adev_dph, res.edf)
    if not any(vals.values()):
        raise FogmonError(f"{rec.name}: no IEEE-952 noise term found for a baseline model")
    model = SensorModel(rec.sample_rate_hz, float(np.mean(y[ok])), Noise(**vals), [],
                        {"origin": f"fogmon explain baseline fitted from {rec.name}"})
    return validate_model(model)
