"""A stationary baseline model from the recording itself, for `fogmon explain` without
``--model``: bias = mean of (rate - 3600 rot_dps) in deg/h, IEEE-952 coefficients from
the engine's weighted fit of the whole-record overlapping ADEV (8 taus per decade);
terms the fit cannot identify are left at 0. No effects: explaining against this
model asks "what in this recording is not stationary IEEE-952 noise?"."""
from __future__ import annotations

import numpy as np

from fogmon.davar.batch import oadev
from fogmon.davar.fit import fit_noise
from fogmon.errors import FogmonError
from fogmon.recording import Recording
from fogmon.sim.model import Noise, SensorModel, validate_model


def baseline_model(rec: Recording) -> SensorModel:
    """Stationary IEEE-952 model (no effects) fitted to ``rec``."""
    blk = rec.to_block()
    y = blk.rate_dph.copy()
    if "rot_dps" in blk.aux:
        y = y - 3600.0 * blk.aux["rot_dps"]
    ok = blk.valid & np.isfinite(y)
    if ok.sum() < 64:
        raise FogmonError(f"{rec.name}: too few valid samples ({int(ok.sum())}) to fit a baseline model")
    fit = fit_noise(oadev(y, rec.sample_rate_hz, taus=8, valid=ok))
    vals = {}
    for name in ("Q_arcsec", "N_dpsh", "B_dph", "K_dphsh", "R_dphh"):
        c = getattr(fit, name)
        v = float(c.value) if bool(c.identifiable) and np.isfinite(c.value) else 0.0
        vals[name] = max(v, 0.0)
    if not any(vals.values()):
        raise FogmonError(f"{rec.name}: no IEEE-952 noise term identifiable for a baseline model")
    model = SensorModel(rec.sample_rate_hz, float(np.mean(y[ok])), Noise(**vals), [],
                        {"origin": f"fogmon explain baseline fitted from {rec.name}"})
    return validate_model(model)
