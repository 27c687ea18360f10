"""IEEE-952 closed forms, Greenhall EDF and chi-square bounds against references."""
import allantools
import numpy as np
import pytest
from allantools.ci import confidence_interval, edf_greenhall

from fogmon.davar.batch import oadev
from fogmon.davar.confidence import chi2_bounds, edf_effective, edf_full, edf_mixture
from fogmon.davar.theory import adev_model, markov_adev, sinusoid_adev


def test_ieee952_read_offs():
    # N = sigma(1 h) in deg/sqrt(h) <=> sigma(tau) = 60 N / sqrt(tau) (tau in s)
    assert adev_model(3600.0, N_dpsh=0.01) == pytest.approx(0.01)
    assert adev_model(1.0, N_dpsh=0.01) == pytest.approx(0.6)
    assert adev_model(10.0, Q_arcsec=2.0) == pytest.approx(np.sqrt(3) * 2.0 / 10.0)
    assert adev_model(123.0, B_dph=1.0) == pytest.approx(0.6643, abs=1e-4)  # flicker floor
    assert adev_model(3.0 * 3600.0, K_dphsh=0.5) == pytest.approx(0.5)  # K = sigma(3 h)
    assert adev_model(np.sqrt(2) * 3600.0, R_dphh=2.0) == pytest.approx(2.0)  # R = sigma(sqrt2 h)
    both = adev_model([1.0, 100.0], N_dpsh=0.01, B_dph=0.1)
    assert both == pytest.approx(np.sqrt([0.36 + 0.4412712 * 0.01, 0.0036 + 0.4412712 * 0.01]), rel=1e-6)


def test_markov_and_sinusoid_peaks():
    tau = np.geomspace(0.01, 100, 200001)
    mk = markov_adev(tau, 2.0, 1.0)
    assert mk.max() == pytest.approx(0.618 * 2.0, rel=2e-3) and tau[mk.argmax()] == pytest.approx(1.89, rel=5e-3)
    sn = sinusoid_adev(tau, 3.0, 10.0)
    assert sn.max() == pytest.approx(0.725 * 3.0, rel=2e-3) and tau[sn.argmax()] == pytest.approx(3.71, rel=5e-3)


def test_markov_formula_matches_simulated_ar1():
    rng = np.random.default_rng(0)
    n, sample_rate_hz, tc, sig = 400000, 10.0, 2.0, 1.5
    a = np.exp(-1 / (sample_rate_hz * tc))
    from scipy.signal import lfilter
    y = lfilter([np.sqrt(1 - a * a) * sig], [1, -a], rng.normal(size=n))
    res = oadev(y, sample_rate_hz, taus=[1.0, 4.0, 16.0])
    # sampled AR(1) differs from the continuous formula by O(tau0 / tau); 3 % with 1-sigma noise
    assert np.allclose(res.adev_dph, markov_adev(res.tau_s, sig, tc), rtol=0.03)


def test_edf_is_greenhall_and_scales_with_gaps():
    m = np.array([1, 3, 16, 250])
    for alpha in (2, 0, -1, -2):
        want = [edf_greenhall(alpha, 2, int(k), 1001, overlapping=True, modified=False) for k in m]
        assert np.allclose(edf_full(alpha, m, 1000), want, rtol=1e-12)
    full = edf_full(0, m, 1000)
    e = edf_effective(full, m, 1000, np.array([999, 0, 484, 1]))  # 999 = all terms at m = 1
    assert e[0] == pytest.approx(full[0]) and np.isnan(e[1])
    assert e[2] == pytest.approx(full[2] * 484 / 969) and e[3] == pytest.approx(full[3] / 501)


def test_edf_is_allantools_greenhall_in_every_case():
    """fogmon evaluates Greenhall's algorithm itself (no allantools or scipy.stats at run
    time): every case of allantools' edf_greenhall for the overlapping ADEV (BasicSum
    with F = m or inf, the long-record tables, the short-record BasicSum, alpha 2 .. -2)."""
    checked = 0
    for n in (8, 20, 64, 257, 1000, 4096, 65536, 10**6):
        for k in sorted({1, 2, 3, 5, 16, 33, 34, 100, 1000, n // 8, n // 3, n // 2}):
            if not 1 <= k <= n // 2:
                continue
            for alpha in (2, 1, 0, -1, -2):
                try:
                    want = edf_greenhall(alpha, 2, k, n + 1, overlapping=True, modified=False)
                except NotImplementedError:  # alpha 2 with under 2 m terms: no EDF either way
                    with pytest.raises(ValueError):
                        edf_full(alpha, k, n)
                    continue
                assert edf_full(alpha, k, n)[0] == pytest.approx(want, rel=1e-12), (alpha, k, n)
                checked += 1
    assert checked > 350


def test_chi2_bounds_match_allantools():
    dev = np.array([1.0, 2.0, 0.5, 3.0])
    edf = np.array([3.0, 17.5, 1000.0, 17.5])
    lo, hi = chi2_bounds(dev, edf, 0.683)
    for d, e, low, h in zip(dev, edf, lo, hi, strict=True):
        rl, rh = confidence_interval(d, e, ci=0.683)
        assert low == pytest.approx(rl, rel=1e-12) and h == pytest.approx(rh, rel=1e-12)
    lo95, hi95 = chi2_bounds(dev, edf, 0.95)
    assert np.all(lo95 < lo) and np.all(hi95 > hi)


def test_oadev_bounds_use_the_fitted_noise_mixture():
    rng = np.random.default_rng(1)
    y = rng.normal(size=200000) + np.cumsum(rng.normal(size=200000)) * 0.01
    res = oadev(y, 1.0, taus="octave")
    # white rate dominates short taus, random walk long ones: the fitted mixture's EDF is
    # white rate noise's exact discrete one there (Greenhall's continuous-time one is 13 %
    # off at m = 1) and the random walk's at the longest taus
    white = edf_mixture(np.tile([0.0, 1.0, 0.0, 0.0], (len(res.m), 1)), res.m, len(y))
    np.testing.assert_allclose(res.edf[res.m < 32], white[res.m < 32], rtol=0.01)
    np.testing.assert_allclose(res.edf[res.m > 4000], edf_full(-2, res.m[res.m > 4000], len(y)), rtol=0.01)
    tau, dev, err, n = allantools.oadev(y, rate=1.0, data_type="freq", taus=res.tau_s)
    assert np.all(res.lo_dph < dev) and np.all(dev < res.hi_dph)


@pytest.mark.parametrize("n", [4096, 2**19])
def test_mixture_edf_of_one_noise_type_is_greenhalls_where_his_is_exact(n):
    m = np.array([1, 2, 3, 8, 33, 64, 200, 257, 1000, 5000, n // 4, n // 2])
    m = m[2 * m <= n]
    for k, alpha in enumerate((2, 0, -1, -2)):
        frac = np.tile(np.eye(4)[k], (len(m), 1))
        # white angle: all m (allantools has no EDF for a single term); white and random
        # walk rate from m = 64 (below, Greenhall's continuous-time form is not the
        # discrete one: see the Monte Carlo test); flicker: Greenhall's form everywhere
        ok = {2: m < n // 2, 0: m >= 64, -1: m > 0, -2: m >= 64}[alpha]
        ref = np.array([edf_greenhall(alpha, 2, int(q), n + 1, overlapping=True) for q in m[ok]])
        # Greenhall's own large-m approximations (F = inf, tables) differ by up to 1.5 %
        np.testing.assert_allclose(edf_mixture(frac, m, n)[ok], ref, rtol=0.016)


def _monte_carlo_edf(y: np.ndarray, m: int) -> float:
    """2 mean^2 / var of the overlapping Allan variance at m over the rows of ``y``."""
    c = np.concatenate([np.zeros((len(y), 1)), np.cumsum(y, axis=1)], axis=1)
    avar = 0.5 * np.mean(((c[:, 2 * m:] - 2 * c[:, m:-m] + c[:, :-2 * m]) / m) ** 2, axis=1)
    return 2.0 * avar.mean() ** 2 / avar.var()


@pytest.mark.parametrize("alpha, m, greenhall_off", [(0, 1, 0.15), (0, 8, -0.08), (-2, 1, -0.2), (-2, 2, -0.1)])
def test_discrete_edf_matches_monte_carlo_where_greenhall_is_off(alpha, m, greenhall_off):
    rng = np.random.default_rng(12)
    e = rng.normal(size=(3000, 2048))
    y = e if alpha == 0 else np.cumsum(e, axis=1)
    mc = _monte_carlo_edf(y, m)
    frac = np.eye(4)[1 if alpha == 0 else 3][None]
    assert edf_mixture(frac, [m], 2048)[0] == pytest.approx(mc, rel=0.08)  # MC: 2.6 % standard error
    g = edf_full(alpha, [m], 2048)[0]
    assert (g / mc - 1) * np.sign(greenhall_off) > abs(greenhall_off) / 2  # the error this fixes


def test_oadev_intervals_use_the_mixture_edf_where_two_noise_types_meet():
    # white angle and white rate noise equal at m = 8: the dominant type's Greenhall EDF
    # (white angle: ~n / 1.94) was 1.4x the mixture's, white rate's 0.45x
    rng = np.random.default_rng(4)
    n, m = 2**16, 8
    y = np.diff(rng.normal(size=n + 1) * np.sqrt(m / 3.0)) + rng.normal(size=n)
    res = oadev(y, 1.0, taus=[1, 2, 4, 8, 16, 32, 64])
    k = list(res.m).index(m)
    assert res.edf[k] == pytest.approx(edf_mixture(np.array([[0.5, 0.5, 0.0, 0.0]]), [m], n)[0], rel=0.1)
    assert edf_full(0, [m], n)[0] * 2 < res.edf[k] < edf_full(2, [m], n)[0] / 1.3


def test_mixture_edf_matches_monte_carlo_of_white_angle_plus_white_rate():
    # at m = 8 white angle noise (Allan variance 3 sx^2 / m^2, tau0 = 1) and white rate
    # noise (1 / m) contribute equally: the EDF is about twice white rate's alone
    rng = np.random.default_rng(11)
    n, m, reps = 4096, 8, 3000
    y = np.diff(rng.normal(size=(reps, n + 1)) * np.sqrt(m / 3.0), axis=1) + rng.normal(size=(reps, n))
    mix = edf_mixture(np.array([[0.5, 0.5, 0.0, 0.0]]), [m], n)[0]
    assert mix == pytest.approx(_monte_carlo_edf(y, m), rel=0.08)  # Monte Carlo: 2.6 % standard error
    assert mix > 1.5 * edf_mixture(np.array([[0.0, 1.0, 0.0, 0.0]]), [m], n)[0]


def test_greenhall_sw_is_eq_7_for_every_noise_type():
    from fogmon.davar.confidence import _sw

    t = np.linspace(-7.0, 7.0, 141)
    a = np.abs(t)
    with np.errstate(divide="ignore", invalid="ignore"):
        lg = np.where(a > 0, np.log(np.where(a > 0, a, 1.0)), 0.0)
    want = {2: -a, 1: t**2 * lg, 0: a**3, -1: t**4 * lg, -2: a**5, -3: t**6 * lg, -4: a**7}
    for alpha, w in want.items():
        np.testing.assert_array_equal(_sw(t, alpha), w)


def _mixture_matrix_one(m: int, n: int) -> np.ndarray:
    """confidence.mixture_matrices of one factor m written out (the reference of the
    form evaluating all factors together): sums over the lags j of (1 - |j| / M) rho_k rho_l."""
    from fogmon.davar.confidence import _GRID_PER_M, _discrete_rho, _sz

    big_m = n - 2 * m + 1
    lag_max = min(3 * m, big_m - 1)
    f = float(m) if m <= _GRID_PER_M else np.inf
    if lag_max <= 3 * _GRID_PER_M:
        j, step = np.arange(-lag_max, lag_max + 1, dtype=np.float64), 1.0
    else:
        j = np.linspace(-lag_max, lag_max, 6 * _GRID_PER_M + 1)
        step = j[1] - j[0]
    spikes = np.arange(-2.0, 3.0)

    def rho(t):
        return np.array([_discrete_rho(m, a, np.round(t * m)) if np.isfinite(f) and a in (0, -2)
                         else _sz(t, f, a) / _sz(np.zeros(1), f, a) for a in (0, -1, -2)])
    r, r_s = rho(j / m), rho(spikes)
    w = step * np.maximum(1.0 - np.abs(j) / big_m, 0.0)
    q = np.maximum(1.0 - np.abs(spikes) * m / big_m, 0.0) * np.array([1.0, -4.0, 6.0, -4.0, 1.0]) / 6.0
    c = np.empty((4, 4))
    c[0, 0] = q @ (np.array([1.0, -4.0, 6.0, -4.0, 1.0]) / 6.0)
    c[0, 1:] = c[1:, 0] = r_s @ q
    c[1:, 1:] = (r * w) @ r.T
    return c


@pytest.mark.parametrize("m, n", [(range(1, 40), 80), ((1, 2, 4, 8, 16, 32, 64, 128, 256, 512), 1030),
                                  (tuple(2 ** k for k in range(15)), 184718), ((3, 100, 257, 300, 5000), 12000)])
def test_mixture_matrices_of_all_factors_at_once_equal_one_factor_at_a_time(m, n):
    from fogmon.davar.confidence import mixture_matrices

    got = mixture_matrices(list(m) + [n], n)
    assert np.isnan(got[-1]).all()  # 2 m > n
    for k, c in zip(m, got, strict=False):  # the noise types' part (the ramp's row: test_davar_fit_covariance)
        np.testing.assert_allclose(c[:4, :4], _mixture_matrix_one(k, n), rtol=1e-12, atol=1e-12 * np.abs(c).max())


def test_no_interval_below_one_edf_and_none_that_excludes_its_estimate():
    # issue 30: "16.48  21.341 [61.635, 1.3915e+12] edf 0.07"
    lo, hi = chi2_bounds(np.array([21.341]), np.array([0.07]))
    assert np.isnan(lo[0]) and np.isnan(hi[0])
    edf = np.geomspace(1.0, 1e6, 200)
    for conf in (0.5, 0.683, 0.9, 0.95, 0.99):
        lo, hi = chi2_bounds(np.ones(len(edf)), edf, conf)
        assert np.all((lo <= 1.0) & (hi >= 1.0))


def _exact_edf(structure, m: int, n: int) -> float:
    """EDF 2 E^2 / var of the overlapping Allan variance at m of n Gaussian rate samples
    whose phase X = cumsum(rate) has the structure function ``structure(t)`` =
    var(X[i + t] - X[i]): the Allan terms' autocovariance at every lag k is
    -1/2 sum_pq c_p c_q D(k + (q - p) m) (c = 1, -2, 1), and var(sum of M squared terms)
    = 2 sum_k (M - |k|) r(k)^2, summed over all M lags: no approximation."""
    big_m = n - 2 * m + 1
    k = np.arange(big_m, dtype=np.float64)
    c = np.array([1.0, -2.0, 1.0])
    r = -0.5 * sum(c[p] * c[q] * structure(np.abs(k + (q - p) * m)) for p in range(3) for q in range(3))
    w = 2.0 * (1.0 - k / big_m)
    w[0] = 1.0
    return big_m / np.sum(w * (r / r[0]) ** 2)


def _ar1_structure(t: np.ndarray, var: float, a: float) -> np.ndarray:
    """var(X[i + t] - X[i]) of the sum X of a stationary AR(1) of variance ``var``, coefficient ``a``."""
    return var * (t * (1.0 + a) / (1.0 - a) - 2.0 * a * (1.0 - a**t) / (1.0 - a) ** 2)


@pytest.mark.parametrize("m", [32, 64])
def test_mixture_edf_is_exact_for_white_angle_plus_white_rate(m):
    # five_100Hz_2.9h of validation/calibration.py at 0.32 and 0.64 s (Q 0.2 arcsec, N 0.005
    # deg/sqrt(h), 100 Hz, 2^20 samples), where the two meet: the mixture EDF is the exact one
    n, fs, q, white = 2**20, 100.0, 0.2, 60.0 * 0.005 * 10.0
    exact = _exact_edf(lambda t: np.where(t > 0, 2.0 * (q * fs) ** 2, 0.0) + white**2 * t, m, n)
    tau = m / fs
    part = np.array([3.0 * q**2 / tau**2, white**2 / fs / tau, 0.0, 0.0])
    assert edf_mixture(part[None] / part.sum(), [m], n)[0] == pytest.approx(exact, rel=1e-9)


def test_mixture_edf_of_white_rate_plus_simulated_flicker_at_the_longest_tau():
    # the simulator's flicker (a sum of Gauss-Markov terms, fogmon.sim.noise.Flicker) under
    # white rate noise at m = n / 4, EDF ~3 (QNB_1kHz_17min of validation/calibration.py at
    # 262 s, scaled): Greenhall's flicker in the mixture gives the process's exact EDF
    import math

    from fogmon.sim.noise import default_flicker_tau_hi_s, flicker_taus

    n, b, white = 2**14, 0.02, 60.0 * 0.00627
    var = b**2 * math.log(2.0) / math.pi
    taus = flicker_taus(1.0, default_flicker_tau_hi_s(1.0, n))
    def structure(t):
        return white**2 * t + sum(_ar1_structure(t, var, math.exp(-1.0 / tc)) for tc in taus)
    for m in (n // 16, n // 4):
        exact = _exact_edf(structure, m, n)
        part = np.array([0.0, white**2 / m, 2.0 * math.log(2.0) / math.pi * b**2, 0.0])
        assert edf_mixture(part[None] / part.sum(), [m], n)[0] == pytest.approx(exact, rel=0.005)
