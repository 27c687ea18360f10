"""The mixture behind a whole record's ADEV intervals (fogmon.davar.record_mixture)."""
import numpy as np

from fogmon.davar import record_mixture
from fogmon.davar.batch import _row_terms, oadev
from fogmon.davar.confidence import RAMP, edf_mixture, term_fractions
from fogmon.davar.theory import coefficients_to_avar_terms
from fogmon.sim.model import Noise, SensorModel
from fogmon.sim.simulate import simulate


def test_a_chance_random_walk_beside_a_ramp_does_not_set_the_edf():
    # N 0.05, B 0.2, R 1 (no K) over 2^15 s at 1 Hz: this record's quick fit puts a random
    # walk beside the ramp, which alone would make the last tau's EDF a twentieth of the truth
    noise = Noise(0.0, 0.05, 0.2, 0.0, 1.0)
    rec = simulate(SensorModel(1.0, noise=noise), duration_s=2**15, seed=11)
    n = len(rec.rate_dph)
    res = oadev(rec.rate_dph, 1.0)
    quick = _row_terms(res.adev_dph**2 * 2 * res.n_terms, res.n_terms, res.m, n)
    true_edf = edf_mixture(term_fractions(coefficients_to_avar_terms(0.0, 0.05, 0.2, 0.0, 1.0), res.tau_s), res.m, n)
    quick_edf = edf_mixture(term_fractions(quick, res.m), res.m, n)
    assert quick[record_mixture.K] > 0 and quick_edf[-1] < true_edf[-1] / 10  # the premise
    assert true_edf[-1] / 1.5 < res.edf[-1] < true_edf[-1] * 1.5


def test_the_rules_move_shares_not_totals():
    a = np.array([0.0, 1.0, 0.5, 0.2, 0.1])  # A_n, tau in sample periods
    m = np.array([1, 4, 16, 64])
    base = term_fractions(a, m)
    none = np.zeros(5, dtype=bool)
    # R not identified: its share counts as random-walk rate noise
    f = record_mixture.fractions(a, none, m)
    np.testing.assert_allclose(f[:, RAMP], 0.0)
    np.testing.assert_allclose(f[:, record_mixture.RANDOM_WALK], base[:, 3] + base[:, RAMP])
    np.testing.assert_allclose(f.sum(1), 1.0)
    # R identified, K not: K from the detrended record; the ramp stays deterministic
    ident = np.array([False, True, True, False, True])
    f = record_mixture.fractions(a, ident, m, k_detrended=0.0)
    np.testing.assert_allclose(f, term_fractions(np.array([0.0, 1.0, 0.5, 0.0, 0.1]), m))
    # both identified: the quick fit's K, and the ramp's share counts as random walk
    f = record_mixture.fractions(a, np.ones(5, dtype=bool), m, k_detrended=0.0)
    np.testing.assert_allclose(f[:, RAMP], 0.0)
    np.testing.assert_allclose(f[:, record_mixture.RANDOM_WALK], base[:, 3] + base[:, RAMP])
