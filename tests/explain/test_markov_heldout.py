"""The held-out check of the ``markov`` kind (a Gauss-Markov term, stationary): fitted on
one half of the record, the term must lower the other half's deviance nearly as much as
that half's own fit (``spectral.STATIONARY_LOSS``). A frequency sweep has excess power
at other frequencies in each half, so no one Gauss-Markov term describes both."""
import numpy as np

from fogmon.explain.analysis import whittle_context
from fogmon.explain.candidates.spectral import STATIONARY_LOSS, markov
from fogmon.explain.selection import _heldout
from fogmon.sim.model import Noise, SensorModel, validate_effect
from fogmon.sim.simulate import simulate

FS = 10.0
FOG = Noise(N_dpsh=0.01, B_dph=0.01)
T = 7200.0


def _ctx(truth: SensorModel, seed: int, extra=None):
    rec = simulate(truth, duration_s=T, seed=seed)
    y = rec.rate_dph + (extra(rec.t_s) if extra else 0.0)
    return whittle_context(SensorModel(FS, 0.0, FOG, []), {}, rec.t_s, np.ones(len(y), bool), y - y.mean())


def test_a_frequency_sweep_is_not_a_gauss_markov_term():
    # 0.5 deg/h swept log-wise from 0.002 to 0.05 Hz over 2 h, under 1.9 deg/h of white
    # noise per sample: the whole record's spectrum fits a 12 s Gauss-Markov term (it
    # was named so), but each half's term misses the other half's band
    f0, f1 = 0.002, 0.05
    k = np.log(f1 / f0) / T

    def chirp(t):
        return 0.5 * np.sin(2 * np.pi * f0 * (np.exp(k * t) - 1) / k)

    ctx = _ctx(SensorModel(FS, 0.0, FOG, []), seed=1, extra=chirp)
    c = markov(ctx)
    assert c is not None and c.bic_gain(ctx.penalty) > 100
    ok, note = _heldout(ctx, c)
    assert not ok, note
    assert f"less {STATIONARY_LOSS}" in note


def test_a_gauss_markov_term_passes():
    for seed, sigma in ((1, 0.6), (2, 0.25)):
        eff = validate_effect("markov", {"tau_c_s": 30.0, "sigma_dph": sigma})
        ctx = _ctx(SensorModel(FS, 0.0, FOG, [eff]), seed=seed)
        c = markov(ctx)
        assert c is not None and 15.0 < c.params["tau_c_s"] < 60.0
        ok, note = _heldout(ctx, c)
        assert ok, note
