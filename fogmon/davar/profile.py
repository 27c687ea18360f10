"""Numba kernels of the IEEE-952 fit's intervals (fogmon/davar/fit.py): the full
five-term fit and, for each term, the generalized score test of A_n = c with every other
term free (>= 0) and refitted under it, so that a term near its detection limit widens
the intervals of the terms it trades off with instead of being fixed at zero.

The test (Boos 1992) belongs to the fit's own estimating equations, Fisher scoring's
U_n = sum_i rw_i x_in (y_i - mu_i) / (v_i mu_i^2) (v = 2 / nu + c2 the relative variance
of the Allan variance y at the model mu): with the other terms refitted under A_n = c,
s(c) = naive_n U_n / sqrt(sandwich_n) - the one-step change of A_n over its sandwich
standard error (``scoring.sandwich_variances``: the exact correlation of the Allan
variances across taus), both evaluated under the hypothesis. s is about standard
normal at the true A_n; it is positive where the record asks for more of the term. A
limit is the c where s reaches a normal quantile.

In a limit's test every other term enters the variance at no less than its floor,
identified or not: a hypothesis may make the mean
fit trade a term away (a rate ramp tested above its estimate pushed the random walk to 0
to stay under the longest taus' Allan variances), but it does not take that term's noise
out of the record; where the hypothesis needs more of a term, the record would hold that
much. A ramp's own Allan variance has no sampling variance, so with the random walk
traded away the variance collapsed and the test became as steep as if the record had
none: on 150 records of all five terms over 2.9 h (K 0.3, R 0.6) s(R true) had sd 1.32
and fell below -1.645 in 12 %, the upper limit of R below the truth in 12 % (in 7 of
those 18 records the refit had put K at 0); with the estimate as a floor, sd 0.88,
0.7 %. Until 2026-11-30 the floor held only for the terms the record identifies, and
the others entered at most at their estimate (a ceiling that took NBR_1Hz_9h's R, no K,
from 97.4 to 96.6 %): beside a strong ramp a real random walk the fit does not identify
(its estimate pulled down, the ramp taking its trends) then left R's test without its
noise, and R's 95 % interval covered 81.7 % of 300 records of K 1, R 3 over 3.6 h at
10 Hz and of all five terms with K 1.5, R 4 over 4.5 h at 1 Hz (59 and 73 % where K was
not identified); with the estimate as the floor 96.3 % on both (validation/calibration.py --held-out,
docs/davar.md "Calibration"). The identification test (s(0)) keeps the refitted variance. (The deviance of the extended
quasi-likelihood, rescaled for the correlation, was used before: its ln v term, v
depending on the terms through the EDF, made it too steep for a ramp beside a random
walk, and its minimum is not that of Fisher scoring.)

The floor is what the record is sure of: a term's estimate less one sandwich standard
error (at least 0), except the random walk K, whose floor is its estimate. Beside a strong
ramp the precision of R hangs on K (a random walk's realized trend is part of the ramp's
estimate) and K's estimate there does not err high, while a near-zero B or R's
nonnegative estimate does: with every estimate as the floor a chance B or R counted as
sure noise (K's 95 % intervals over-covered), and with K's floor lowered too R's
intervals on the held-out K-and-R models covered 86 % (the coverage numbers:
docs/davar.md, "Calibration").

A nuisance term at its bound (Self & Liang 1987). Where the refit under A_n = c holds
another term q at 0 because the data ask for less, s is the score with q fixed, not
projected out: with rho the correlation of the two scores (the free terms projected
out, ``boundary_correlation``), s = sqrt(1 - rho^2) Z1 + rho Z2 given Z2 < 0 when q's
truth is 0 (where the refit frees q, s is the score with q projected out, independent of
q's score: standard normal). For a term the record identifies, the limits read s through
that distribution (``boundary_z``, rho > 0: terms that trade off, N and Q, K and R): it
lies below the normal, so a limit at the normal quantile came out low. On NBK_10Hz_1.8h
of validation/calibration.py (Q 0, held at 0 in 75 % of the refits at the true N, rho
about 0.87) s at the true N had mean -0.28 (sd 0.95, 200 records) and N's upper limit
covered 91.0 % of 300 records (92.1 % of 1000); read through the boundary distribution,
95.3 % (96.1 %). Where q's truth is above 0 but the refit holds it at 0, the shift is
smaller: the rule errs high for an upper limit, low for a lower one. A term the record does not
identify keeps the normal quantile: the upper limits of the terms identified in under
half of a model's records already covered 97.7-100 % (300 records per model; few EDF at
the long taus make s conservative), and the rule widened them further (QNB_1kHz_17min B
97.7 % -> 99.3 %, its 95 % interval 96.3 % -> 97.3 %).
"""
from __future__ import annotations

import math

import numpy as np

from fogmon.davar.scoring import (
    _model,
    avar_sd,
    fisher_scoring,
    information_and_meat,
    mixture_correlation,
    mixture_edf,
    robust_scoring,
    sandwich_variances,
    symmetric_pinv,
)
from fogmon.davar.theory import NAMES
from fogmon.jit import B1, F1, F2, F3, F4, F8, I8, kernel

_ALL = np.ones(5, np.bool_)
_MAX_BRACKET = 60  # doublings of the step above the estimate
_MIN_STEP = 1e-6  # the first step above the estimate, at least this fraction of it
_MAX_ROOT = 40  # regula falsi steps
_Z_CAP = 37.0
_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)  # Gauss-Legendre nodes and weights on [-1, 1]
_K = NAMES.index("K_dphsh")  # the random walk's column


@kernel(error_model="numpy")
def signed_score(x, y, mats, full, gap_scale, cov, rw, c2, start, n, c, rtol, max_iter, estimate, floored):
    """(s(c), rho, the terms refitted under A_n = c) for term ``n``: Fisher scoring of the
    other terms (>= 0) from ``start`` with A_n held at ``c``, then the signed root of the
    generalized score statistic (module docstring) over the terms > 0 and n. With
    ``floored`` (a limit's test), another term that the refit lowers below its value in
    ``estimate`` (its floor, ``_floor``) enters the variance (the sandwich's standard
    deviations and correlation across taus) at that value. ``rho``: the largest
    correlation of s with the score of a term the refit holds at its bound 0
    (``boundary_correlation``; -1 when none is), for ``boundary_z``."""
    a0 = start.copy()
    a0[n] = c
    cols = _ALL.copy()
    cols[n] = False
    # from the data as model when nothing else is left (the estimate held only term n, tested at 0)
    a1, model, nu = fisher_scoring(x, cols, y, mats, full, gap_scale, rw, a0, not np.any(a0 > 0), c2, rtol, max_iter)
    u = 0.0
    for i in range(x.shape[0]):
        u += rw[i] * x[i, n] * (y[i] - model[i]) / ((2.0 / nu[i] + c2) * model[i] ** 2)
    free = a1 > 0
    free[n] = True
    noise = a1.copy()
    squeezed = False
    for j in range(5):
        if floored and j != n and a1[j] < estimate[j]:
            noise[j] = estimate[j]
            squeezed = True
    if squeezed:
        sd = avar_sd(_model(x, noise, 1e-300, np.empty(x.shape[0])), mixture_edf(x, noise, mats, full, gap_scale), c2)
    else:
        sd = avar_sd(model, nu, c2)
    corr = mixture_correlation(x, noise, cov)
    naive, sand = sandwich_variances(x, model, corr, free, rw, nu, c2, sd)
    k = 0
    for j in range(n):
        k += free[j]
    if not (naive[k] > 0 and sand[k] > 0):
        return 0.0, -1.0, a1
    return naive[k] * u / np.sqrt(sand[k]), boundary_correlation(x, model, corr, free, n, rw, nu, c2, sd), a1


@kernel(error_model="numpy")
def boundary_correlation(x, model, corr, free, n, rw, nu, c2, sd):
    """The largest, over the terms q held at their bound 0 (not ``free``; ``n`` is), of the
    correlation of the scores U_n and U_q with the free terms projected out (U* = U_nq -
    I_nq,G I_GG^-1 U_G, G the free terms but n; covariance = the sandwich's meat): the
    one-step changes d = B U over the free terms and q (B = the inverse information) have
    the 2 x 2 block d_nq = B_nq U*, so cov(U*) = B_nq^-1 cov(d_nq) B_nq^-1. -1 when no
    term is at its bound (or its block is singular)."""
    best = -1.0
    for q in range(5):
        if q == n or free[q]:
            continue
        cols = free.copy()
        cols[q] = True
        info, meat, _ = information_and_meat(x, model, corr, cols, rw, nu, c2, sd)
        kn = 0
        kq = 0
        for j in range(5):
            kn += cols[j] and j < n
            kq += cols[j] and j < q
        bread = symmetric_pinv(info)
        b00, b01, b11 = bread[kn, kn], bread[kn, kq], bread[kq, kq]
        det = b00 * b11 - b01 * b01
        if not det > 1e-12 * b00 * b11:
            continue
        i00, i01, i11 = b11 / det, -b01 / det, b00 / det  # B_nq^-1
        s00, s01, s11 = _sandwich(bread, meat, kn, kn), _sandwich(bread, meat, kn, kq), _sandwich(bread, meat, kq, kq)
        c00 = i00 * (i00 * s00 + i01 * s01) + i01 * (i00 * s01 + i01 * s11)
        c11 = i01 * (i01 * s00 + i11 * s01) + i11 * (i01 * s01 + i11 * s11)
        c01 = i00 * (i01 * s00 + i11 * s01) + i01 * (i01 * s01 + i11 * s11)
        if c00 > 0 and c11 > 0:
            best = max(best, c01 / np.sqrt(c00 * c11))
    return best


@kernel()
def _sandwich(bread, meat, i, j):
    """Entry (i, j) of bread @ meat @ bread (symmetric k x k) by plain loops: numba's
    ``@`` calls BLAS through scipy, which the ahead-of-time build (setup.py) has not."""
    k = bread.shape[0]
    acc = 0.0
    for a in range(k):
        row = 0.0
        for b in range(k):
            row += meat[a, b] * bread[b, j]
        acc += bread[i, a] * row
    return acc


@kernel(error_model="numpy")
def boundary_z(s, rho):
    """The normal quantile of s's probability under its null distribution when a nuisance
    term whose score correlates ``rho`` with s is held at its bound 0 (Self & Liang 1987,
    the truth on the boundary): there s = sqrt(1 - rho^2) Z1 + rho Z2 given Z2 < 0 (Z1, Z2
    independent standard normal; Z2 the nuisance's standardized score, < 0 where the data
    ask for less than 0), whose CDF is 2 Phi2(s, 0; rho) = Phi(s) + (1 / pi) int_0^asin(rho)
    exp(-s^2 / (2 cos^2 t)) dt (Owen's T; Gauss-Legendre). s itself when rho <= 0 (no
    nuisance at its bound, or one that shifts s up: the normal quantile is then conservative
    for an upper limit)."""
    if not rho > 0.0:
        return s
    top = np.arcsin(min(rho, 1.0))
    area = 0.0
    for i in range(_GL_X.shape[0]):
        t = 0.5 * top * (_GL_X[i] + 1.0)
        area += _GL_W[i] * np.exp(-s * s / (2.0 * np.cos(t) ** 2))
    area *= 0.5 * top / np.pi
    p_lo = 0.5 * math.erfc(-s / math.sqrt(2.0)) + area  # P(S <= s)
    p_hi = 0.5 * math.erfc(s / math.sqrt(2.0)) - area  # P(S > s)
    z = _normal_quantile(p_lo) if p_lo <= p_hi else -_normal_quantile(p_hi)
    return min(max(z, -_Z_CAP), _Z_CAP)  # finite for the regula falsi (p below 1e-300 where rho -> 1)


@kernel(error_model="numpy")
def _normal_quantile(p):
    """z with Phi(z) = p for p <= 0.5 (-inf at 0): Newton on ln Phi, concave, from
    -sqrt(-2 ln p) below the root (Phi(-x) <= exp(-x^2 / 2) / 2), converging from below."""
    if not p > 0.0:
        return -np.inf
    z = -math.sqrt(-2.0 * math.log(p))
    for _ in range(60):
        phi = 0.5 * math.erfc(-z / math.sqrt(2.0))
        step = (math.log(phi) - math.log(p)) * phi / (math.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi))
        z -= step
        if abs(step) < 1e-12 * max(1.0, abs(z)):
            break
    return z


@kernel((F2, F1, F3, F1, F1, F4, F1, F8, F1, F1, B1, F8, F1, F1, F8, I8), error_model="numpy")
def score_limits(x, y, mats, full, gap_scale, cov, rw, c2, a, se, which, identify_z, lower_z, upper_z, rtol,
                 max_iter):
    """For each term n in ``which``: s(0) (``signed_score``; <= 0 when the estimate A_n is
    0; the record identifies the term when s(0) > ``identify_z``), and the limits: for
    each normal quantile z of ``lower_z`` the c in [0, A_n] where z(c) = z (0 when z(0) <=
    z), for each z of ``upper_z`` (increasing) the c > A_n where z(c) = -z (inf when no
    bracket is found in _MAX_BRACKET doublings), z(c) = ``boundary_z`` of s(c) for a term
    identified, s(c) for one not (module docstring), every other term counting in the
    variance of each s(c) at no less than its floor (``_floor``). Brackets start at A_n + its sandwich standard error
    ``se`` (at least _MIN_STEP A_n); Illinois regula falsi to 1e-3 of the bracket's top (of A_n below it); each fit
    is warm-started from the last. Returns (s0 (5,), lower (5, len(lower_z)), upper (5,
    len(upper_z))), NaN outside ``which``."""
    s0 = np.full(5, np.nan)
    rho = np.full(5, -1.0)
    lower = np.full((5, lower_z.shape[0]), np.nan)
    upper = np.full((5, upper_z.shape[0]), np.nan)
    present = np.zeros(5, np.bool_)
    for n in range(5):
        if not which[n]:
            continue
        s, rho[n], _ = signed_score(x, y, mats, full, gap_scale, cov, rw, c2, a, n, 0.0, rtol, max_iter, a, False)
        s0[n] = s if a[n] > 0 else min(s, 0.0)  # the fit put the term at 0: the record does not ask for it
    for n in range(5):
        present[n] = s0[n] > identify_z
    fl = _floor(a, se)
    for n in range(5):
        if not which[n]:
            continue
        a_n = a[n]
        z0 = boundary_z(s0[n], rho[n]) if present[n] else s0[n]
        for k in range(lower_z.shape[0]):
            z = lower_z[k]
            if not z0 > z:
                lower[n, k] = 0.0
                continue
            lower[n, k] = _root(x, y, mats, full, gap_scale, cov, rw, c2, a, n, rtol, max_iter, fl, present, z,
                                0.0, z0 - z, a_n, -z, 1e-3 * a_n)
        # a standard error below A_n's float resolution (a degenerate sandwich: a pure-Q
        # fit of the G ring laser, se / A 1e-19) would leave the bracket at A_n for ever
        step = max(se[n], _MIN_STEP * a_n) if se[n] > 0 and np.isfinite(se[n]) else max(a_n, 1e-300)
        lo, s_lo, hi = a_n, 0.0, a_n + step
        start = a.copy()
        for k in range(upper_z.shape[0]):
            z = upper_z[k]
            if lo > a_n and not s_lo > -z:  # the last bracket's bottom is already past this quantile
                lo, s_lo = a_n, 0.0
            found = False
            s_hi = 0.0
            for _ in range(_MAX_BRACKET):
                s_hi, r, start = signed_score(x, y, mats, full, gap_scale, cov, rw, c2, start, n, hi, rtol,
                                              max_iter, fl, True)
                if present[n]:
                    s_hi = boundary_z(s_hi, r)
                if s_hi < -z:
                    found = True
                    break
                lo, s_lo, hi = hi, s_hi, hi + 2.0 * (hi - a_n)
            if not found:
                upper[n, k:] = np.inf
                break
            upper[n, k] = _root(x, y, mats, full, gap_scale, cov, rw, c2, start, n, rtol, max_iter, fl, present, -z,
                                lo, s_lo + z, hi, s_hi + z, 1e-3 * hi)
            lo, s_lo = upper[n, k], -z  # the next quantile's bracket starts at this limit
    return s0, lower, upper


@kernel(error_model="numpy")
def _floor(a, se):
    """Each term's floor in a limit's variance (module docstring): A_n - se_n (at least 0),
    K's its estimate A_K."""
    out = a.copy()
    for j in range(5):
        if j != _K and np.isfinite(se[j]):
            out[j] = max(0.0, a[j] - se[j])
    return out


@kernel(error_model="numpy")
def _root(x, y, mats, full, gap_scale, cov, rw, c2, start, n, rtol, max_iter, estimate, present, target, lo, f_lo, hi,
          f_hi, tol):
    """The c in [lo, hi] where z(c) (``score_limits``) of term n crosses ``target``,
    given f = z - target at both ends of opposite signs: Illinois regula falsi to ``tol`` (or |f| < 1e-3)."""
    side = 0
    c = 0.5 * (lo + hi)
    for _ in range(_MAX_ROOT):
        if hi - lo <= tol:
            break
        c = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        c = min(max(c, lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
        s, rho, start = signed_score(x, y, mats, full, gap_scale, cov, rw, c2, start, n, c, rtol, max_iter,
                                     estimate, True)
        f = (boundary_z(s, rho) if present[n] else s) - target
        if abs(f) < 1e-3:
            return c
        if (f > 0) == (f_hi > 0):
            hi, f_hi = c, f
            if side == 1:
                f_lo /= 2.0
            side = 1
        else:
            lo, f_lo = c, f
            if side == -1:
                f_hi /= 2.0
            side = -1
    return c


@kernel((F2, F1, F3, F1, F1, F4, F2, F8, F8, F8, F8, I8, F8, F8, I8), error_model="numpy")
def fit_full(x, y, mats, full, gap_scale, cov, starts, tukey_c, floor2, gate, rw_tol, max_robust, robust_rtol, rtol,
             max_iter):
    """The five-term fit of fit.fit_avar on its taus: ``robust_scoring`` of all five terms
    from the robust weights ``starts``, the winner scored to ``rtol``. Standard errors:
    sandwich (``sandwich_variances`` with the exact correlation across taus of the
    covariance matrices ``cov``) over the terms > 0; a term at 0 gets the one it would have
    if fitted alongside them. Returns (found, A, se, robust weights, c2); found False when
    every robust start failed."""
    every = _ALL.copy()   # a writable mask: a global is a read-only array in numba (a second version)
    found, a, rw, c2 = robust_scoring(x, every, y, mats, full, gap_scale, starts, tukey_c, floor2, gate, rw_tol,
                                      max_robust, robust_rtol, max_iter)
    se = np.full(5, np.inf)
    if not found:
        return False, a, se, rw, c2
    a, model, nu = fisher_scoring(x, every, y, mats, full, gap_scale, rw, a, not np.any(a > 0), c2, rtol, max_iter)
    corr = mixture_correlation(x, a, cov)
    sd = avar_sd(model, nu, c2)
    for n in range(5):
        cols = a > 0
        cols[n] = True
        k = 0
        for j in range(n):
            k += cols[j]
        se[n] = np.sqrt(sandwich_variances(x, model, corr, cols, rw, nu, c2, sd)[1][k])
    return True, a, se, rw, c2
