"""Numba kernels of the per-window statistics formed from finished window sums (the sums
of squared Allan terms, (deg/h)^2, and their valid-term counts that fogmon/davar/kernels.py
and fogmon/davar/running_sums.py make): adev = sqrt(sum / (2 count)) in deg/h
(``frame_stats``, ``adev_in_place``: NaN without terms; ``frame_stats`` also counts the
entries with fewer terms than a gap-free window, whose EDF the caller scales) and the z-test
of measured Allan variances against a model's, (deg/h)^2 per averaging factor m (samples)
(``model_holds``).
"""
from __future__ import annotations

import numpy as np

from fogmon.jit import F1, F2, F8, I1, I2, kernel


@kernel((F1, F1, I1, I1, F8), error_model="numpy")
def model_holds(model, sums, counts, m, hold_z):
    """|ln(avar / model)| <= hold_z sqrt(2 m / n + 0.01) at every tau with n > 0 terms,
    avar = max(sum, 0) / (2 n) (deg/h)^2, ``model`` the model's Allan variance per tau."""
    for k in range(m.shape[0]):
        n = counts[k]
        if n > 0:
            z = np.log(max(sums[k], 0.0) / (2.0 * n) / model[k]) / np.sqrt(2.0 * m[k] / n + 0.01)
            if not abs(z) <= hold_z:
                return False
    return True


_ROWS = 16  # rows per flat loop of ``frame_stats`` (one counts row)


@kernel((F2, I2, I1, F2), error_model="numpy")
def frame_stats(sums, counts, full, adev):
    """One pass over windows (rows) x taus: adev = sqrt(sum / (2 count)) (NaN without
    terms) into ``adev`` (shape of ``sums``; ``adev`` may be ``sums`` itself, at 3.5-4 x the
    time, measured: the vectoriser's overlap check fails, see ``adev_in_place``; ``counts``
    may be one row for all); returns the number of entries with fewer than ``full`` terms (their EDF is
    scaled by the caller). 1 / (2 count) is formed first, once per row of counts, so the
    inner loop multiplies, branch-free (SIMD; a division per entry, or forming it inside
    the loop, ran it 2 x slower)."""
    nt, nm = sums.shape
    inv = np.empty((counts.shape[0], nm))
    n_gapped = 0
    for i in range(counts.shape[0]):
        c = counts[i]
        for k in range(nm):
            inv[i, k] = 1.0 / (2.0 * c[k])  # 1 / 0 = inf: NaN below
            n_gapped += c[k] != full[k]
    last = counts.shape[0] - 1
    i0 = 0
    if last == 0:
        n_gapped *= nt
        # one counts row: rows in chunks of _ROWS, each one flat loop over _ROWS x nm
        # entries (a row of nm leaves a scalar remainder per row: 1.8 x the time at 46 taus)
        i0 = nt - nt % _ROWS
        if i0 > 0:
            rep = np.empty(_ROWS * nm)
            for r in range(_ROWS):
                rep[r * nm:(r + 1) * nm] = inv[0]
            s_flat, a_flat = sums[:i0].reshape(i0 * nm), adev[:i0].reshape(i0 * nm)
            for j0 in range(0, i0 * nm, _ROWS * nm):
                s, a = s_flat[j0:j0 + _ROWS * nm], a_flat[j0:j0 + _ROWS * nm]
                for j in range(_ROWS * nm):
                    a[j] = np.sqrt(max(s[j], 0.0) * rep[j])
    for i in range(i0, nt):
        iv, s, a_row = inv[min(i, last)], sums[i], adev[i]
        for k in range(nm):
            a_row[k] = np.sqrt(max(s[k], 0.0) * iv[k])
    return n_gapped


@kernel((F2, I2), error_model="numpy")
def adev_in_place(values, counts):
    """``frame_stats`` over its own input, the same values: the window sums of squared
    terms ``values`` (rows) become adev = sqrt(sum / (2 count)) in place (``counts``: one
    row for all, or one per row). One array read and written, as fast as two apart
    (``frame_stats`` given one array twice: 3.5-4 x slower); no new array (at hop 1 its
    3 MB per block of 8192 windows cost a reader of every window ~20 %, measured)."""
    nt, nm = values.shape
    last = counts.shape[0] - 1
    inv = np.empty((last + 1, nm))
    for i in range(last + 1):
        for k in range(nm):
            inv[i, k] = 1.0 / (2.0 * counts[i, k])  # 1 / 0 = inf: NaN below
    i0 = nt - nt % _ROWS if last == 0 else 0
    if i0 > 0:  # one counts row: rows in chunks of _ROWS, one flat loop each (see frame_stats)
        rep = np.empty(_ROWS * nm)
        for r in range(_ROWS):
            rep[r * nm:(r + 1) * nm] = inv[0]
        flat = values[:i0].reshape(i0 * nm)
        for j0 in range(0, i0 * nm, _ROWS * nm):
            a = flat[j0:j0 + _ROWS * nm]
            for j in range(_ROWS * nm):
                a[j] = np.sqrt(max(a[j], 0.0) * rep[j])
    for i in range(i0, nt):
        iv, a = inv[min(i, last)], values[i]
        for k in range(nm):
            a[k] = np.sqrt(max(a[k], 0.0) * iv[k])
