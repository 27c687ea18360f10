"""The exact-shape ADEV interval at the longest taus (fogmon.davar.shape) against the exact
distribution of the Allan variance: the eigenvalues of its quadratic form in the samples."""
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import gammainc
from scipy.stats import ncx2

from fogmon.davar.batch import oadev
from fogmon.davar.confidence import chi2_bounds, chi2_factors, edf_mixture
from fogmon.davar.shape import quantiles, shape_applies, shape_factors


def _term_covariance(n: int, m: int, kind: str) -> np.ndarray:
    """Covariance of the overlapping Allan terms of factor m of n rate samples that are
    white ("white"), a random walk ("walk") or the differences of white phase ("phase"),
    normalised to a mean variance of 1."""
    if kind == "phase":
        y = np.diff(np.eye(n + 1), axis=0)
    else:
        y = np.eye(n) if kind == "white" else np.tril(np.ones((n, n)))
    x = np.vstack([np.zeros((1, y.shape[1])), np.cumsum(y, axis=0)])
    j = np.arange(n - 2 * m + 1)
    h = x[j + 2 * m] - 2 * x[j + m] + x[j]
    c = h @ h.T
    return c / np.mean(np.diag(c))


def _exact_cdf(lam: np.ndarray, x: float) -> float:
    """P(sum_k lam_k z_k^2 <= x), Imhof's (1961) inversion of the characteristic function."""
    def f(u):
        theta = 0.5 * np.arctan(lam * u).sum() - 0.5 * x * u
        return np.sin(theta) / (u * np.prod((1.0 + (lam * u) ** 2) ** 0.25))
    return 0.5 - quad(f, 0.0, np.inf, limit=5000)[0] / np.pi


def _exact_coverage(mix: dict, n: int, m: int, confidence: float, fractions: np.ndarray) -> tuple[float, float]:
    """Probability that the shape and the chi-square intervals of the mixture ``mix``
    (kind -> variance share) cover the true Allan variance, from the exact eigenvalues."""
    cov = sum(share * _term_covariance(n, m, kind) for kind, share in mix.items())
    lam = np.clip(np.linalg.eigvalsh(cov / len(cov)), 0.0, None)
    lam /= lam.sum()
    edf = 1.0 / np.sum(lam**2)
    assert edf == pytest.approx(edf_mixture(fractions[None, :4], [m], n)[0], rel=1e-3)  # the EDF is exact
    out = []
    for f_lo, f_hi in (shape_factors(fractions[None], [m], n, np.array([edf]), confidence),
                       chi2_factors(np.array([edf]), confidence)):
        # sigma^2 in [s^2 f_lo^2, s^2 f_hi^2] <=> X = s^2 / sigma^2 in [1 / f_hi^2, 1 / f_lo^2]
        out.append(_exact_cdf(lam, 1.0 / f_lo[0] ** 2) - _exact_cdf(lam, 1.0 / f_hi[0] ** 2))
    return out[0], out[1]


@pytest.mark.parametrize(("mix", "fractions", "tol"), [
    ({"white": 1.0}, np.array([0.0, 1.0, 0.0, 0.0, 0.0]), 0.005),
    ({"walk": 1.0}, np.array([0.0, 0.0, 0.0, 1.0, 0.0]), 0.005),
    ({"white": 0.5, "walk": 0.5}, np.array([0.0, 0.5, 0.0, 0.5, 0.0]), 0.005),
    # white angle noise taken as a constant: 94.5 % at 95 %
    ({"phase": 0.3, "white": 0.7}, np.array([0.3, 0.7, 0.0, 0.0, 0.0]), 0.006),
])
def test_shape_interval_covers_at_its_level_at_m_n_over_4(mix, fractions, tol):
    n, m = 256, 64  # M / m = 2: a handful of eigenvalues carry the Allan variance
    for confidence in (0.683, 0.95):
        shape, chi2 = _exact_coverage(mix, n, m, confidence, fractions)
        assert shape == pytest.approx(confidence, abs=tol), (mix, confidence)
        assert chi2 > confidence + 0.015  # chi-square of the same (exact) EDF covers too much here


def test_shape_interval_at_more_terms():
    shape, chi2 = _exact_coverage({"white": 1.0}, 1024, 64, 0.683, np.array([0.0, 1.0, 0.0, 0.0, 0.0]))
    assert shape == pytest.approx(0.683, abs=0.004) and chi2 == pytest.approx(0.692, abs=0.003)


def test_saddlepoint_quantiles_match_chi2_and_noncentral_chi2():
    """The Lugannani-Rice quantiles hold their probability to 0.003 from 2 degrees of freedom on."""
    q = np.array([0.025, 0.1585, 0.8415, 0.975])
    for k in (2, 5, 30):
        x = quantiles(np.full(k, 1.0 / k), np.zeros(k), 0.0, q)
        np.testing.assert_allclose(gammainc(k / 2.0, k * x / 2.0), q, atol=0.003 if k == 2 else 3e-4)
    # 4 equal eigenvalues with a mean along them (a ramp) and a constant (white angle noise)
    lam, nc = np.full(4, 0.15), 3.0
    x = quantiles(lam, lam * nc / 4.0, 0.2, q)
    np.testing.assert_allclose(ncx2.cdf((x - 0.2) / 0.15, 4, nc), q, atol=1e-3)


def test_oadev_takes_the_shape_at_the_longest_taus_only():
    rng = np.random.default_rng(3)
    n = 2**12
    y = rng.normal(size=n)
    res = oadev(y, 1.0)  # the default: the exact shape at the longest taus
    lo, hi = chi2_bounds(res.adev_dph, res.edf)
    plain = oadev(y, 1.0, exact_shape=False)  # chi-square everywhere
    np.testing.assert_array_equal(plain.edf, res.edf)
    np.testing.assert_array_equal(plain.lo_dph, lo)
    np.testing.assert_array_equal(plain.hi_dph, hi)
    shaped = shape_applies(res.m, n)
    assert shaped.sum() == 3  # m = n/16, n/8, n/4 (M / m = 14, 6, 2)
    np.testing.assert_array_equal(lo[~shaped], res.lo_dph[~shaped])
    np.testing.assert_array_equal(hi[~shaped], res.hi_dph[~shaped])
    # white rate noise at m = n / 4: the exact shape is narrower than chi-square's at both ends
    assert lo[-1] < res.lo_dph[-1] < res.adev_dph[-1] < res.hi_dph[-1] < hi[-1]


@pytest.mark.parametrize(("terms", "deterministic"), [
    ([0.0, 1.0, 0.0, 0.0, 0.0], False),  # white rate noise
    ([1e-3, 1.0, 1e-2, 1e-4, 0.0], False),  # four noise types
    ([0.0, 1.0, 0.0, 1e-5, 1e-9], True),  # a deterministic ramp beside a random walk
])
def test_dense_grid_shape_is_interpolated_within_0_3_percent_of_the_exact(terms, deterministic):
    # an "all" grid of 2^15 samples: the shape exact at the anchors (8 per octave), interpolated
    # between them, against the exact shape of each tau computed alone (took 26 s for all 6372)
    from fogmon.davar.record_mixture import edf_row, fractions
    n = 2**15
    m = np.arange(1, n // 4 + 1)
    f = fractions(np.array(terms), deterministic, m)
    edf = edf_row(f, m, n)
    for confidence in (0.683, 0.95):
        lo, hi = shape_factors(f, m, n, edf, confidence)
        shaped = np.flatnonzero(np.isfinite(lo))
        assert len(shaped) == np.count_nonzero(shape_applies(m, n))
        for i in shaped[::97]:
            one_lo, one_hi = shape_factors(f[i:i + 1], m[i:i + 1], n, edf[i:i + 1], confidence)
            assert lo[i] == pytest.approx(one_lo[0], rel=3e-3) and hi[i] == pytest.approx(one_hi[0], rel=3e-3)


def test_an_octave_grid_takes_every_tau_shape_exactly():
    from fogmon.davar.record_mixture import edf_row, fractions
    n = 2**15
    m = 2 ** np.arange(15)[2 ** np.arange(15) <= n // 4]
    f = fractions(np.array([0.0, 1.0, 0.0, 1e-4, 0.0]), False, m)
    edf = edf_row(f, m, n)
    lo, hi = shape_factors(f, m, n, edf, 0.95)
    for i in np.flatnonzero(np.isfinite(lo)):
        one_lo, one_hi = shape_factors(f[i:i + 1], m[i:i + 1], n, edf[i:i + 1], 0.95)
        assert lo[i] == pytest.approx(one_lo[0], rel=1e-12) and hi[i] == pytest.approx(one_hi[0], rel=1e-12)
