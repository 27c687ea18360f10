"""Covariance of overlapping Allan variances across taus (the fit's sandwich intervals):
exact quadratic-form reference, Monte Carlo, and agreement with the mixture EDF."""
import numpy as np
import pytest
from scipy.signal import fftconvolve

from fogmon.davar.batch import oadev
from fogmon.davar.confidence import avar_relative_covariance, covariance_matrices, edf_mixture


def _term_matrix(m: int, n: int) -> np.ndarray:
    """Rows: the overlapping Allan terms of factor m as filters of n rate samples."""
    d = np.zeros((n - 2 * m + 1, n))
    for j in range(n - 2 * m + 1):
        d[j, j:j + m], d[j, j + m:j + 2 * m] = -1.0 / m, 1.0 / m
    return d


def test_relative_covariance_equals_the_exact_quadratic_form():
    # q_m = y'A_m y with A_m = D_m'D_m / (2 M): cov(q_a, q_b) = 2 tr(A_a S A_b S), E q = tr(A S);
    # S = sum of white angle (D D'), white rate (I) and random-walk rate (L L') covariances
    n = 256
    m = np.array([1, 2, 3, 7, 16, 30, 50, 64])  # 30-64: lag segments past 48, the quadrature path
    diff = np.eye(n, n + 1, 1) - np.eye(n, n + 1)
    walk = np.tril(np.ones((n, n)))
    parts = [diff @ diff.T, np.eye(n), 1e-3 * walk @ walk.T]
    a = [_term_matrix(k, n).T @ _term_matrix(k, n) / (2.0 * (n - 2 * k + 1)) for k in m]
    s = sum(parts)
    mean = np.array([np.trace(ak @ s) for ak in a])
    b = [ak @ s for ak in a]
    ref = np.array([[2.0 * np.sum(bi * bj.T) for bj in b] for bi in b]) / np.outer(mean, mean)
    frac = np.array([[np.trace(ak @ p) for p in parts] for ak in a]) / mean[:, None]
    assert np.all(frac.max(axis=0) > 0.5)  # each class dominates some taus: a real mixture
    frac = np.column_stack([frac[:, 0], frac[:, 1], np.zeros(len(m)), frac[:, 2]])
    got = avar_relative_covariance(frac, covariance_matrices(m, n), n - 2 * m + 1)
    np.testing.assert_allclose(got, ref, rtol=5e-4)  # measured 1.2e-4: midpoint error of the quadrature


def test_a_rate_ramp_adds_only_its_cross_term_with_the_noise():
    # y = mu + e, mu a ramp: q_m = y'A_m y has mean mu'A mu + tr(A S) and covariance
    # 2 tr(A_a S A_b S) + 4 mu'A_a S A_b mu: the ramp's own part mu'A mu has no variance
    n = 256
    m = np.array([1, 2, 3, 7, 16, 30, 50, 64])
    diff = np.eye(n, n + 1, 1) - np.eye(n, n + 1)
    walk = np.tril(np.ones((n, n)))
    parts = [diff @ diff.T, np.eye(n), 1e-3 * walk @ walk.T]
    s = sum(parts)
    mu = 0.01 * np.arange(n)
    a = [_term_matrix(k, n).T @ _term_matrix(k, n) / (2.0 * (n - 2 * k + 1)) for k in m]
    ramp = np.array([mu @ ak @ mu for ak in a])
    mean = np.array([np.trace(ak @ s) for ak in a]) + ramp
    b = [ak @ s for ak in a]
    ref = (np.array([[2.0 * np.sum(bi * bj.T) for bj in b] for bi in b])
           + 4.0 * np.array([[mu @ bi @ aj @ mu for aj in a] for bi in b])) / np.outer(mean, mean)
    noise = np.array([[np.trace(ak @ p) for p in parts] for ak in a])
    frac = np.column_stack([noise[:, 0], noise[:, 1], np.zeros(len(m)), noise[:, 2], ramp]) / mean[:, None]
    assert frac[:, 4].max() > 0.5  # the ramp dominates the longest taus
    got = avar_relative_covariance(frac, covariance_matrices(m, n), n - 2 * m + 1)
    np.testing.assert_allclose(got, ref, rtol=5e-4)
    np.testing.assert_allclose(edf_mixture(frac, m, n), 2.0 / np.diag(ref), rtol=5e-3)  # lags to 3 m only


def _avars(y: np.ndarray, m: np.ndarray) -> np.ndarray:
    c = np.concatenate([np.zeros((len(y), 1)), np.cumsum(y, axis=1)], axis=1)
    return np.array([0.5 * np.mean(((c[:, 2 * k:] - 2 * c[:, k:-k] + c[:, :-2 * k]) / k) ** 2, axis=1)
                     for k in m]).T


def test_flicker_correlation_across_octaves_matches_monte_carlo():
    # Kasdin's discrete flicker; the continuous (Greenhall) form holds from m ~ 16
    rng = np.random.default_rng(21)
    n, reps = 4096, 1500
    m = np.array([16, 32, 64, 128, 256])
    k = np.arange(1, n)
    h = np.concatenate([[1.0], np.cumprod((k - 0.5) / k)])
    y = fftconvolve(rng.normal(size=(reps, n)), h[None, :], axes=1)[:, :n]
    q = _avars(y, m)
    emp = np.corrcoef(q.T)
    got = avar_relative_covariance(np.tile([0.0, 0.0, 1.0, 0.0], (len(m), 1)), covariance_matrices(m, n),
                                   n - 2 * m + 1)
    corr = got / np.sqrt(np.outer(np.diag(got), np.diag(got)))
    # Monte Carlo standard error of a correlation ~ (1 - rho^2) / sqrt(reps) <= 0.026
    np.testing.assert_allclose(corr[np.triu_indices(len(m), 1)], emp[np.triu_indices(len(m), 1)], atol=0.08)
    assert corr[0, 1] == pytest.approx(0.68, abs=0.05) and corr[0, 2] == pytest.approx(0.33, abs=0.05)
    var_ratio = np.var(q / q.mean(axis=0), axis=0) / np.diag(got)
    assert np.all(np.abs(var_ratio - 1.0) < 0.12)  # variance of a variance: ~4 % standard error


def test_diagonal_is_the_mixture_edf():
    n = 2**16
    m = 2 ** np.arange(15)
    rng = np.random.default_rng(2)
    frac = rng.dirichlet(np.ones(4), size=len(m))
    frac[:8, 2] = 0.0  # flicker: Greenhall's finite-m form below m = 256, the continuous one here
    frac /= frac.sum(axis=1, keepdims=True)
    cov = avar_relative_covariance(frac, covariance_matrices(m, n), n - 2 * m + 1)
    np.testing.assert_allclose(2.0 / np.diag(cov), edf_mixture(frac, m, n), rtol=5e-3)


def test_dense_grids_fit_one_tau_per_octave():
    # "all" and 20 per decade are fitted on the taus nearest each octave: the same
    # identification and (all: exactly, 20/decade: nearly) the same fit as the octave grid
    from fogmon.davar import fit as fit_mod
    rng = np.random.default_rng(8)
    n, sample_rate_hz = 2**14, 100.0
    y = np.diff(rng.normal(size=n + 1) * 0.05) * sample_rate_hz + rng.normal(size=n) * 0.3 * np.sqrt(sample_rate_hz)
    fits = {}
    for grid in ("octave", 20, "all"):
        res = oadev(y, sample_rate_hz, taus=grid)
        fits[grid] = fit_mod.fit_avar(res.tau_s, res.adev_dph**2, res.m, res.n_terms, n)
    a, se, _, _ = fits["octave"]
    assert (a[:2] > 0).all()
    for grid in (20, "all"):
        assert np.array_equal(fits[grid][0] > 0, a > 0), grid
    np.testing.assert_allclose(fits["all"][0], a, rtol=1e-9)
    np.testing.assert_allclose(fits[20][0][:2], a[:2], rtol=0.05)
    m_all = oadev(y, sample_rate_hz, taus="all").m
    assert np.array_equal(m_all[fit_mod.octave_subset(m_all, n // 4)], 2 ** np.arange(13))


def test_dense_grid_edf_is_the_exact_edf_within_a_fraction_of_a_percent():
    # exact mixture EDF at 8 taus per octave, interpolated between: checked against the
    # exact EDF at every m of an "all" grid (1/4 of m up to 2^10) for five noise mixtures
    from fogmon.davar.fit import _NoiseModel, dense_grid_edf
    n = 2**12
    m = np.r_[np.arange(1, 65), np.arange(65, n // 4 + 1, 4)].astype(np.int64)
    tau = m / 100.0
    n_terms = n - 2 * m + 1
    n_terms[::7] //= 2  # gaps: the EDF scales with the valid terms
    exact = _NoiseModel(tau, m, n_terms, n)
    for a in ([0, 1e-2, 0, 0, 0], [0, 1e-2, 1e-4, 0, 0], [1e-4, 1e-3, 0, 0, 0], [0, 1e-3, 0, 1e-7, 0],
              [1e-5, 1e-3, 1e-5, 1e-8, 1e-10]):
        a = np.array(a, dtype=np.float64)
        np.testing.assert_allclose(dense_grid_edf(a, tau, m, n_terms, n), exact(a), rtol=2e-3)


def _pair_lags_one(ma: int, mb: int, n_a: int, n_b: int) -> tuple[np.ndarray, np.ndarray]:
    """confidence._pair_lags of one pair written segment by segment (the reference of its
    vectorised form)."""
    from fogmon.davar.confidence import _EXACT_SEGMENT, _GAUSS_W, _GAUSS_X

    kinks = (np.arange(3)[:, None] * ma - np.arange(3)[None, :] * mb).ravel()
    lo = max(kinks.min() - 4 * max(ma, mb), -(n_a - 1))
    hi = min(kinks.max() + 4 * max(ma, mb), n_b - 1) + 1
    knots = np.unique(np.clip(np.concatenate([kinks, [lo, hi, 0, n_b - n_a]]), lo, hi))
    lags, wts = [], []
    for a, b in zip(knots[:-1], knots[1:], strict=True):
        if b - a <= _EXACT_SEGMENT:
            lags.append(np.arange(a, b, dtype=np.float64))
            wts.append(np.ones(b - a))
        else:
            half = 0.5 * (b - a - 1)
            lags += [np.array([float(a)]), half * _GAUSS_X + 0.5 * (a + b)]
            wts += [np.ones(1), half * _GAUSS_W]
    return np.concatenate(lags), np.concatenate(wts)


@pytest.mark.parametrize("m, n", [((1, 2, 3, 7, 16, 30, 50, 64), 256), ((1, 2, 4, 8, 16, 32, 64, 128), 300),
                                  (tuple(2 ** k for k in range(15)), 184718), ((1, 5, 100, 1000, 4000), 8001)])
def test_vectorised_lag_grids_and_term_covariances_equal_the_pair_by_pair_forms(m, n):
    from fogmon.davar.confidence import _SECOND_DIFF, _pair_lags, _phase_acv, _term_xcov_raw

    ia, ib = np.triu_indices(len(m))
    ma, mb = np.array(m)[ia], np.array(m)[ib]
    pair, lag, w = _pair_lags(ma, mb, n - 2 * ma + 1, n - 2 * mb + 1)
    for i, (a, b) in enumerate(zip(ma.tolist(), mb.tolist(), strict=True)):
        want_lag, want_w = _pair_lags_one(a, b, n - 2 * a + 1, n - 2 * b + 1)
        np.testing.assert_array_equal(lag[pair == i], want_lag)
        np.testing.assert_array_equal(w[pair == i], want_w)
    got = _term_xcov_raw(lag, ma[pair], mb[pair])
    for k, alpha in enumerate((0, -1, -2)):  # sum over p, q of d_p d_q acv(lag + q mb - p ma)
        want = sum(_SECOND_DIFF[p] * _SECOND_DIFF[q] * _phase_acv(lag + q * mb[pair] - p * ma[pair], alpha)
                   for p in range(3) for q in range(3))
        np.testing.assert_allclose(got[k], want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
