"""Numba kernels of the IEEE-952 fit (fogmon/davar/fit.py): the Fisher-scoring iteration
with the mixture-EDF weights and the small non-negative least-squares problems it solves
(at most 5 columns, Lawson & Hanson with Householder least squares), its robust
reweighting and the sandwich variances (the intervals' score tests: fogmon/davar/profile.py),
so that an iteration costs microseconds instead of a hundred of Python and scipy overhead."""
from __future__ import annotations

import numpy as np

from fogmon.jit import B1, BOOL, F1, F2, F3, F8, I8, kernel

_CLASS = np.array([0, 1, 2, 3, 4])
"""Class of each term Q, N, B, K, R in the mixture matrices: the noise types
confidence.MIX_ALPHAS, then the deterministic ramp (confidence.RAMP)."""
_N_CLASSES = 5  # confidence.N_CLASSES
_EPS = 2.0**-52
_MIN_RELVAR = 1e-12
"""Floor of f'Cf (the relative variance of an Allan variance x M / 2): a model that is all
ramp (no noise) would otherwise have an infinite EDF."""


@kernel()
def _nonzero(mask, out):
    """Write the indices of the True entries of ``mask`` to ``out``; returns their count.
    (The kernels are plain loops: numpy's array functions, fancy indexing and array
    expressions each cost numba a compile of their own on the first run.)"""
    n = 0
    for j in range(mask.shape[0]):
        if mask[j]:
            out[n] = j
            n += 1
    return n


@kernel()
def _model(x, a, floor, out):
    """out = x a (rows of ``x``: tau^n), at least ``floor`` (NaN stays NaN); returns ``out``."""
    for i in range(x.shape[0]):
        v = 0.0
        for j in range(x.shape[1]):
            v += x[i, j] * a[j]
        out[i] = v if not v < floor else floor
    return out


@kernel()
def _where(mask, a, out):
    """out[j] = a[j] where ``mask[j]``, else 0 (numpy.where(mask, a, 0.0)); returns ``out``."""
    for j in range(mask.shape[0]):
        out[j] = a[j] if mask[j] else 0.0
    return out


@kernel()
def _filled(n, value):
    """An array of n times ``value``."""
    out = np.empty(n)
    for i in range(n):
        out[i] = value
    return out


@kernel()
def _positive(a, out):
    """out[j] = a[j] > 0; returns ``out``."""
    for j in range(a.shape[0]):
        out[j] = a[j] > 0
    return out


@kernel()
def _converged(new, old, rtol):
    """max |new / old - 1| < rtol (False when a ratio is NaN)."""
    for i in range(new.shape[0]):  # noqa: SIM110 - numba compiles no generator into all()
        if not abs(new[i] / old[i] - 1.0) < rtol:
            return False
    return True


@kernel()
def _least_squares(a, b):
    """x minimising |a x - b| (n x k, n >= k) by Householder QR; 0 for a column that is
    dependent on the ones before it. Plain loops (array expressions cost numba several
    times the compile)."""
    n, k = a.shape
    r = a.copy()
    q = b.copy()
    v = np.empty(n)
    for j in range(k):
        norm = 0.0
        for i in range(j, n):
            norm += r[i, j] ** 2
        norm = np.sqrt(norm)
        if norm == 0.0:
            continue
        alpha = -norm if r[j, j] > 0 else norm
        vv = 0.0
        for i in range(j, n):
            v[i] = r[i, j] - (alpha if i == j else 0.0)
            vv += v[i] * v[i]
        if vv == 0.0:
            continue
        for c in range(j, k + 1):  # the columns of r, then q
            s = 0.0
            for i in range(j, n):
                s += v[i] * (r[i, c] if c < k else q[i])
            f = 2.0 * s / vv
            for i in range(j, n):
                if c < k:
                    r[i, c] -= f * v[i]
                else:
                    q[i] -= f * v[i]
    x = np.zeros(k)
    scale = 0.0
    for j in range(k):
        scale = max(scale, abs(r[j, j]))
    for j in range(k - 1, -1, -1):
        s = q[j]
        for c in range(j + 1, k):
            s -= r[j, c] * x[c]
        x[j] = s / r[j, j] if abs(r[j, j]) > 1e-14 * scale else 0.0
    return x


@kernel()
def nnls(a, b):
    """x >= 0 minimising |a x - b| (Lawson & Hanson's active-set algorithm; columns of
    ``a`` normalised by the caller). A column whose entry would not be positive is
    skipped until x changes (no cycling)."""
    n, k = a.shape
    x = np.zeros(k)
    passive = np.zeros(k, np.bool_)
    skip = np.zeros(k, np.bool_)
    idx = np.empty(k, np.int64)
    a_max = 0.0
    for i in range(n):
        for j in range(k):
            if abs(a[i, j]) > a_max:
                a_max = abs(a[i, j])
    tol = 10.0 * _EPS * max(n, k) * max(1.0, a_max)
    for _ in range(4 * k + 4):
        w = np.zeros(k)
        for i in range(n):
            res = b[i]
            for j in range(k):
                res -= a[i, j] * x[j]
            for j in range(k):
                w[j] += a[i, j] * res
        j_max = -1
        w_max = tol
        for j in range(k):
            if not passive[j] and not skip[j] and w[j] > w_max:
                w_max, j_max = w[j], j
        if j_max < 0:
            break
        passive[j_max] = True
        s = np.zeros(k)
        first = True
        for _inner in range(3 * k + 3):
            n_p = _nonzero(passive, idx)
            for j in range(k):
                s[j] = 0.0
            if n_p == 0:
                break
            a_p = np.empty((n, n_p))
            for i in range(n):
                for c in range(n_p):
                    a_p[i, c] = a[i, idx[c]]
            s_p = _least_squares(a_p, b)
            all_positive = True
            for c in range(n_p):
                all_positive &= s_p[c] > tol
            if all_positive:
                for c in range(n_p):
                    s[idx[c]] = s_p[c]
                break
            c_new = 0
            while idx[c_new] != j_max:
                c_new += 1
            if first and s_p[c_new] <= tol:
                passive[j_max] = False  # the new column does not enter: try the next one
                skip[j_max] = True
                for j in range(k):
                    s[j] = x[j]
                break
            first = False
            step = np.inf
            for i in range(n_p):
                if s_p[i] <= tol:
                    d = x[idx[i]] - s_p[i]
                    step = min(step, x[idx[i]] / d if d > 0 else 0.0)
            for i in range(n_p):
                x[idx[i]] += step * (s_p[i] - x[idx[i]])
            for i in range(n_p):
                if x[idx[i]] <= tol:
                    passive[idx[i]] = False
                    x[idx[i]] = 0.0
        if not skip[j_max]:
            for j in range(k):
                skip[j] = False
        x = s
    return x


@kernel(error_model="numpy")
def mixture_fractions(x, a):
    """Share (taus x 5) of each class (``_CLASS``: the noise types, then the ramp) in the
    model Allan variance sum_n A_n tau^n per tau (rows of ``x``: tau^n): white rate noise
    where the model is empty."""
    t = x.shape[0]
    f = np.zeros((t, _N_CLASSES))
    for i in range(t):
        total = 0.0
        for n in range(5):
            c = x[i, n] * a[n]
            total += c
            f[i, _CLASS[n]] += c
        for u in range(_N_CLASSES):
            f[i, u] = f[i, u] / total if total > 0 else 0.0
        if not total > 0:
            f[i, 1] = 1.0
    return f


@kernel((F2, F1, F3, F1, F1), error_model="numpy")
def mixture_edf(x, a, mats, full, gap_scale):
    """EDF per tau of the noise mixture the model A (5 terms; rows of ``x``: tau^n)
    predicts (``mixture_fractions``): full / f'Mf scaled for gaps
    (confidence.edf_mixture_from with the mixture matrices ``mats``)."""
    t = x.shape[0]
    nu = np.empty(t)
    f = mixture_fractions(x, a)
    for i in range(t):
        q = 0.0
        for u in range(_N_CLASSES):
            for v in range(_N_CLASSES):
                q += f[i, u] * mats[i, u, v] * f[i, v]
        nu[i] = full[i] / max(q, _MIN_RELVAR) * gap_scale[i]
    return nu


@kernel(error_model="numpy")
def mixture_correlation(x, a, cov):
    """Correlation (taus x taus) of the Allan variance estimates across the taus (rows of
    ``x``) for the noise mixture of the model A: confidence.avar_relative_covariance
    from its ``covariance_matrices`` ``cov``, normalised to unit diagonal (where the
    term counts cancel)."""
    f = mixture_fractions(x, a)
    t = f.shape[0]
    c = np.empty((t, t))
    g = np.empty(_N_CLASSES)
    for p in range(t):
        for q in range(p, t):
            for k in range(_N_CLASSES):
                g[k] = np.sqrt(f[p, k] * f[q, k])
            s = 0.0
            for k in range(_N_CLASSES):
                for v in range(_N_CLASSES):
                    s += g[k] * cov[p, q, k, v] * g[v]
            c[p, q] = s
            c[q, p] = s
    for p in range(t):
        c[p, p] = max(c[p, p], _MIN_RELVAR)
    sd = np.empty(t)
    for p in range(t):
        sd[p] = np.sqrt(c[p, p])
    for p in range(t):
        for q in range(t):
            c[p, q] /= sd[p] * sd[q]
    return c


@kernel()
def symmetric_pinv(a):
    """Pseudo-inverse of a small symmetric matrix from its eigen-decomposition by cyclic
    Jacobi rotations: eigenvalues within 1e-15 of the largest in magnitude count as zero
    (numpy.linalg.pinv's default cut-off of the singular values). Plain loops: numba's
    LAPACK binding would add ~9 CPU s to the first run's compile for a 5 x 5 matrix.
    NaN everywhere when ``a`` holds a non-finite value (where numpy's SVD raises)."""
    k = a.shape[0]
    d = a.copy()
    v = np.zeros((k, k))
    finite = True
    for p in range(k):
        v[p, p] = 1.0
        for q in range(k):
            finite &= np.isfinite(a[p, q])
    if not finite:
        for p in range(k):
            for q in range(k):
                d[p, q] = np.nan
        return d
    for _ in range(64):
        off = 0.0
        norm = 0.0
        for p in range(k):
            norm += d[p, p] ** 2
            for q in range(p + 1, k):
                off += d[p, q] ** 2
        if not off > 1e-36 * norm:
            break
        for p in range(k):
            for q in range(p + 1, k):
                if d[p, q] == 0.0:
                    continue
                theta = (d[q, q] - d[p, p]) / (2.0 * d[p, q])
                if abs(theta) > 1e150:
                    t = 0.5 / theta
                else:
                    t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                    if theta < 0:
                        t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for r in range(k):
                    drp, drq = d[r, p], d[r, q]
                    d[r, p] = c * drp - s * drq
                    d[r, q] = s * drp + c * drq
                for r in range(k):
                    dpr, dqr = d[p, r], d[q, r]
                    d[p, r] = c * dpr - s * dqr
                    d[q, r] = s * dpr + c * dqr
                for r in range(k):
                    vrp, vrq = v[r, p], v[r, q]
                    v[r, p] = c * vrp - s * vrq
                    v[r, q] = s * vrp + c * vrq
    cut = 0.0
    for p in range(k):
        cut = max(cut, 1e-15 * abs(d[p, p]))
    out = np.zeros((k, k))
    for p in range(k):
        if abs(d[p, p]) > cut:
            for r in range(k):
                for q in range(k):
                    out[r, q] += v[r, p] * v[q, p] / d[p, p]
    return out


@kernel()
def avar_sd(model, nu, c2):
    """Standard deviations model sqrt(2 / nu + c2) of Allan variances of expectation
    ``model`` and EDF ``nu`` (c2: model-inadequacy variance)."""
    sd = np.empty(model.shape[0])
    for i in range(model.shape[0]):
        sd[i] = model[i] * np.sqrt(2.0 / nu[i] + c2)
    return sd


@kernel(error_model="numpy")
def information_and_meat(x, model, corr, cols, rw, nu, c2, sd):
    """(info, meat, scale) of the EDF-weighted estimator over the terms ``cols`` (mask over
    the 5 columns of x, weights rw / ((2 / nu + c2) model^2)), the columns scaled to unit
    weighted norm (``scale``: their norms sqrt(sum w x^2), as ``fisher_scoring`` scales
    them; the plain norm where that is 0), so that info has a unit diagonal and
    ``symmetric_pinv``'s cut-off compares correlations, not units (docs/davar.md, "Noise
    fit"): info = X'WX, the information of the independence likelihood, and meat = G'
    corr G (G = WX sd), the covariance of the scores with the Allan variances' standard
    deviations ``sd`` and correlation across taus ``corr``."""
    idx = np.empty(cols.shape[0], np.int64)
    t, k = x.shape[0], _nonzero(cols, idx)
    xs = np.empty((t, k))
    wx = np.empty((t, k))
    g = np.empty((t, k))
    scale = np.zeros(k)
    weight = np.empty(t)
    for i in range(t):
        weight[i] = rw[i] / ((2.0 / nu[i] + c2) * model[i] ** 2)
    for j in range(k):
        plain = 0.0
        for i in range(t):
            plain += x[i, idx[j]] ** 2
            if weight[i] > 0 and np.isfinite(weight[i]):
                scale[j] += weight[i] * x[i, idx[j]] ** 2
        scale[j] = np.sqrt(scale[j]) if scale[j] > 0 and np.isfinite(scale[j]) else np.sqrt(plain)
    for i in range(t):
        w = weight[i]
        for j in range(k):
            xs[i, j] = x[i, idx[j]] / scale[j]
            wx[i, j] = w * xs[i, j]
            g[i, j] = wx[i, j] * sd[i]
    info = np.zeros((k, k))
    meat = np.zeros((k, k))
    for p in range(k):
        for q in range(p, k):
            s_info = 0.0
            s_meat = 0.0
            for i in range(t):
                s_info += xs[i, p] * wx[i, q]
                inner = 0.0
                for u in range(t):
                    inner += corr[i, u] * g[u, q]
                s_meat += g[i, p] * inner
            info[p, q] = s_info
            info[q, p] = s_info
            meat[p, q] = s_meat
            meat[q, p] = s_meat
    return info, meat, scale


@kernel(error_model="numpy")
def sandwich_variances(x, model, corr, cols, rw, nu, c2, sd):
    """Variances of A over the terms ``cols`` (mask over the 5 columns of x) of the
    EDF-weighted estimator (weights rw / ((2 / nu + c2) model^2)): (naive, sandwich).
    Naive: the inverse information of the independence likelihood, (X'WX)^-1 (columns
    scaled to unit norm; ``symmetric_pinv``). Sandwich: with the Allan variances'
    standard deviations ``sd`` (model sqrt(2 / nu + c2) under the fitted mixture, c2 the
    model-inadequacy variance) and their exact correlation across taus ``corr`` (applied
    to the inadequacy part too: a misfit is smooth in tau); ``information_and_meat``."""
    info, meat, scale = information_and_meat(x, model, corr, cols, rw, nu, c2, sd)
    k = scale.shape[0]
    bread = symmetric_pinv(info)
    naive = np.empty(k)
    sand = np.empty(k)
    for p in range(k):
        acc = 0.0
        for q in range(k):
            for r in range(k):
                acc += bread[p, q] * meat[q, r] * bread[r, p]
        naive[p] = max(bread[p, p], 0.0) / scale[p] ** 2
        sand[p] = max(acc, 0.0) / scale[p] ** 2
    return naive, sand


@kernel((F2, B1, F1, F3, F1, F1, F1, F1, BOOL, F8, F8, I8), error_model="numpy")
def fisher_scoring(x, cols, y, mats, full, gap_scale, rw, a, from_data, c2, rtol, max_iter):
    """Fisher scoring of the terms ``cols`` (mask over the 5 columns of x) >= 0 with the
    other terms held at their values in ``a``, robust weights ``rw``, model-inadequacy
    variance ``c2``: weights sqrt(rw / (2 / nu + c2)) / model, nu the mixture EDF of the
    current model (``mixture_edf``); from the data as model (``from_data``) or from
    ``a``, until the model moves less than ``rtol`` (at most ``max_iter`` steps).
    Returns (A, model, nu at A). Rows with non-finite weights are left out of a step;
    a column without weight gets 0."""
    t, n_terms = x.shape
    a = a.copy()
    model = np.empty(t)
    if from_data:
        for j in range(n_terms):
            a[j] = 0.0
        for i in range(t):
            model[i] = y[i]
    else:
        _model(x, a, 1e-300, model)
    free = np.empty(n_terms, np.int64)
    n_free = _nonzero(cols, free)
    fixed = a.copy()
    for c in range(n_free):
        fixed[free[c]] = 0.0
    offset = _model(x, fixed, -np.inf, np.empty(t))
    sw = np.empty(t)
    rows = np.empty(t, np.int64)
    use = np.empty(n_terms, np.int64)
    scale = np.zeros(n_terms)
    for _ in range(max_iter):
        nu = mixture_edf(x, a, mats, full, gap_scale)
        for i in range(t):
            sw[i] = np.sqrt(rw[i] / (2.0 / nu[i] + c2)) / model[i]
        a_new = fixed.copy()
        if n_free:
            n_rows = 0
            for i in range(t):
                ok = np.isfinite((y[i] - offset[i]) * sw[i])
                for c in range(n_free):
                    ok &= np.isfinite(x[i, free[c]] * sw[i])
                if ok:
                    rows[n_rows] = i
                    n_rows += 1
            m_ = np.empty((n_rows, n_free))
            b_ = np.empty(n_rows)
            for r in range(n_rows):
                i = rows[r]
                b_[r] = (y[i] - offset[i]) * sw[i]
                for c in range(n_free):
                    m_[r, c] = x[i, free[c]] * sw[i]
            n_use = 0
            for c in range(n_free):
                ss = 0.0
                for r in range(n_rows):
                    ss += m_[r, c] * m_[r, c]
                scale[c] = np.sqrt(ss)
                if scale[c] > 0:
                    use[n_use] = c
                    n_use += 1
            if n_use:
                m_use = np.empty((n_rows, n_use))
                for r in range(n_rows):
                    for c in range(n_use):
                        m_use[r, c] = m_[r, use[c]] / scale[use[c]]
                sol = nnls(m_use, b_)
                for c in range(n_use):
                    a_new[free[use[c]]] = sol[c] / scale[use[c]]
        model_new = _model(x, a_new, 1e-300, np.empty(t))
        done = _converged(model_new, model, rtol)
        a, model = a_new, model_new
        if done:
            break
    return a, model, mixture_edf(x, a, mats, full, gap_scale)


@kernel()
def excess_variance_root(r2w, v, dof):
    """The c2 >= 0 where sum r2w / (v + c2) = dof (Paule-Mandel), for sum r2w / v > dof:
    Newton's method from c2 = 0, monotone for this convex decreasing function, to full
    precision."""
    c2 = 0.0
    for _ in range(200):
        f = 0.0
        g = 0.0
        for i in range(r2w.shape[0]):
            q = r2w[i] / (v[i] + c2)
            f += q
            g += q / (v[i] + c2)
        step = (f - dof) / g
        c2 += step
        if step <= 1e-15 * c2:
            break
    return c2


@kernel()
def _excess_variance(r, v, rw, n_free, gate):
    """Model-inadequacy variance c2 of ln(Allan variance) from the residuals ``r`` and
    sampling variances ``v`` of the taus kept (rw > 0): the Paule-Mandel root
    (``excess_variance_root``) when their reduced chi-square exceeds ``gate``, else 0."""
    chi = 0.0
    n = 0
    for i in range(r.shape[0]):
        if rw[i] > 0:
            chi += rw[i] * r[i] ** 2 / v[i]
            n += 1
    dof = max(n - n_free, 1)
    if not chi > gate * dof:
        return 0.0
    r2w = np.empty(n)
    v_kept = np.empty(n)
    k = 0
    for i in range(r.shape[0]):
        if rw[i] > 0:
            r2w[k] = rw[i] * r[i] ** 2
            v_kept[k] = v[i]
            k += 1
    return excess_variance_root(r2w, v_kept, float(dof))


@kernel(error_model="numpy", inline="always")
def robust_scoring(x, cols, y, mats, full, gap_scale, starts, tukey_c, floor2, gate, rw_tol, max_robust,
                   rtol, max_iter):
    """Robust Fisher scoring of the terms ``cols``: from each row of ``starts`` (robust
    weights), Fisher scoring (to ``rtol``) reweighted by Tukey's biweight (cut-off
    ``tukey_c``) of z = ln(y / model) / sqrt(2 / nu + floor2), with the Paule-Mandel
    excess variance (``gate``), until the weights move less than ``rw_tol`` and c2 by
    less than 1e-3 of itself (at most ``max_robust`` rounds); keeps the start with the
    least Tukey loss (an earlier one wins ties), stops at a start that ends rejecting no
    tau (not at one that failed: its weights kept fewer than two taus). Returns (found,
    A, robust weights, c2) of the winner (found False: every start kept fewer than two
    taus)."""
    t = y.shape[0]
    best_a = np.zeros(5)
    best_rw = np.zeros(t)
    best_c2 = 0.0
    best_loss = np.inf
    found = False
    for s in range(starts.shape[0]):
        rw = starts[s].copy()
        a = np.zeros(5)
        have_a = False
        c2 = 0.0
        total_loss = np.nan
        for _ in range(max_robust):
            from_data = not have_a
            if have_a:
                from_data = True
                for j in range(5):
                    if cols[j] and a[j] > 0:
                        from_data = False
                a0 = _where(cols, a, np.empty(5))
            else:
                a0 = np.zeros(5)
            a, model, nu = fisher_scoring(x, cols, y, mats, full, gap_scale, rw, a0, from_data, c2, rtol, max_iter)
            have_a = True
            rw_new = np.empty(t)
            total_loss = 0.0
            n_kept = 0
            r = np.empty(t)
            v = np.empty(t)
            for i in range(t):
                r[i] = np.log(y[i] / model[i])
                v[i] = 2.0 / nu[i]
            for i in range(t):
                z = r[i] / np.sqrt(v[i] + floor2)
                u2 = (z / tukey_c) ** 2
                if u2 > 1.0:
                    u2 = 1.0
                rw_new[i] = (1.0 - u2) ** 2
                total_loss += 1.0 - (1.0 - u2) ** 3
                n_kept += rw_new[i] > 0
            if n_kept < 2:
                total_loss = np.inf
                break
            n_free = 0
            for j in range(5):
                n_free += a[j] > 0
            c2_new = _excess_variance(r, v, rw_new, n_free, gate)
            done = True
            for i in range(t):
                done &= abs(rw_new[i] - rw[i]) < rw_tol
            done &= abs(c2_new - c2) <= 1e-3 * c2
            rw, c2 = rw_new, c2_new
            if done:
                break
        if total_loss < best_loss - 1e-9:
            best_a, best_rw, best_c2, best_loss = a, rw, c2, total_loss
            found = True
        if not total_loss < np.inf:
            # a failed start (its weights kept fewer than two taus; ``rw`` is still the start's
            # own, all ones for the first) rejected everything: it must not end the search
            continue
        all_kept = True
        for i in range(t):
            all_kept &= rw[i] > 0
        if all_kept:
            break
    return found, best_a, best_rw, best_c2
