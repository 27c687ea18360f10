"""Numba kernels of the Allan-variance engines.

Conventions: a *term* of averaging factor m starting at sample j is
``(sum y[j+m : j+2m] - sum y[j : j+m]) / m`` (deg/h), computed from prefix sums ``P`` of
``y - ref`` (invalid samples contribute 0). It is valid when the prefix count ``bad`` of
invalid samples does not change over ``[j, j+2m)``. Running sums are compensated
(Knuth TwoSum: ``s`` plus the accumulated rounding errors ``c``).
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _two_sum(s, x):
    """Return (s + x, rounding error of that addition)."""
    t = s + x
    bp = t - s
    return t, (s - (t - bp)) + (x - bp)


@njit(cache=True)
def prefix_sums_dd(y, valid, ref):
    """Double-double prefix sums of ``y - ref`` over valid samples (``hi``, ``lo``, n+1 each)
    and the prefix count of invalid samples (n+1)."""
    n = y.shape[0]
    hi = np.empty(n + 1)
    lo = np.empty(n + 1)
    bad = np.empty(n + 1, np.int64)
    s = 0.0
    c = 0.0
    b = 0
    hi[0] = 0.0
    lo[0] = 0.0
    bad[0] = 0
    for i in range(n):
        if valid[i]:
            s, e = _two_sum(s, y[i] - ref)
            c += e
        else:
            b += 1
        hi[i + 1] = s
        lo[i + 1] = c
        bad[i + 1] = b
    return hi, lo, bad


@njit(cache=True, inline="always")
def _term_dd(hi, lo, j, m):
    a = j + m
    b = j + 2 * m
    return (((hi[b] - hi[a]) - (hi[a] - hi[j])) + ((lo[b] - lo[a]) - (lo[a] - lo[j]))) / m


@njit(cache=True)
def window_sums(hi, lo, bad, ms, starts, w):
    """Sums of squared valid terms and valid-term counts (T x M) for windows of ``w``
    samples starting at ``starts`` (increasing), by differencing compensated cumulative
    sums of squared terms: O(N) per m for all windows."""
    nt = starts.shape[0]
    nm = ms.shape[0]
    sums = np.zeros((nt, nm))
    counts = np.zeros((nt, nm), np.int64)
    s_at = np.empty(nt)
    c_at = np.empty(nt)
    n_at = np.empty(nt, np.int64)
    for k in range(nm):
        m = ms[k]
        if nt == 0 or 2 * m > w:
            continue
        span = w - 2 * m + 1  # terms per window
        j_end = starts[nt - 1] + span  # one past the last term needed
        s = 0.0
        c = 0.0
        cnt = 0
        pa = 0
        pb = 0
        for j in range(j_end + 1):
            while pa < nt and starts[pa] == j:
                s_at[pa] = s
                c_at[pa] = c
                n_at[pa] = cnt
                pa += 1
            while pb < nt and starts[pb] + span == j:
                sums[pb, k] = (s - s_at[pb]) + (c - c_at[pb])
                counts[pb, k] = cnt - n_at[pb]
                pb += 1
            if j == j_end:
                break
            if bad[j + 2 * m] == bad[j]:
                t = _term_dd(hi, lo, j, m)
                s, e = _two_sum(s, t * t)
                c += e
                cnt += 1
    return sums, counts


@njit(cache=True)
def stream_append(y, valid, yraw, vraw, psum, bad, length, ref):
    """Append samples to the linear buffer: raw values, validity, prefix sums of
    ``y - ref`` over valid samples and prefix counts of invalid samples."""
    s = psum[length]
    b = bad[length]
    for i in range(y.shape[0]):
        p = length + i
        yraw[p] = y[i]
        vraw[p] = valid[i]
        if valid[i]:
            s += y[i] - ref
        else:
            b += 1
        psum[p + 1] = s
        bad[p + 1] = b


@njit(cache=True)
def stream_update(first, n_new, w, ms, psum, bad, sum_s, sum_c, cnt, emit_pos, out_sums, out_counts):
    """Slide the window over buffer positions ``first .. first + n_new - 1`` (already
    appended; the buffer holds at least the ``w - 1`` samples before ``first`` or starts
    at the record's first sample, position 0 then meaning absolute index 0). For every m
    the term ending at each new sample enters and the term starting at the sample that
    left leaves; at the buffer positions ``emit_pos`` (increasing) the current sums and
    counts are written to the rows of ``out_sums``/``out_counts``."""
    n_emit = emit_pos.shape[0]
    for k in range(ms.shape[0]):
        m = ms[k]
        s = sum_s[k]
        c = sum_c[k]
        n = cnt[k]
        e = 0
        for p in range(first, first + n_new):
            jn = p - 2 * m + 1
            if jn >= 0 and bad[p + 1] == bad[jn]:
                t = ((psum[p + 1] - psum[p + 1 - m]) - (psum[p + 1 - m] - psum[jn])) / m
                s, err = _two_sum(s, t * t)
                c += err
                n += 1
            jo = p - w
            if jo >= 0 and bad[jo + 2 * m] == bad[jo]:
                t = ((psum[jo + 2 * m] - psum[jo + m]) - (psum[jo + m] - psum[jo])) / m
                s, err = _two_sum(s, -(t * t))
                c += err
                n -= 1
            if e < n_emit and emit_pos[e] == p:
                out_sums[e, k] = s + c
                out_counts[e, k] = n
                e += 1
        sum_s[k] = s
        sum_c[k] = c
        cnt[k] = n


@njit(cache=True)
def stream_reanchor(yraw, vraw, psum, bad, length, w, ms, sum_s, sum_c, cnt):
    """Keep the last ``w`` samples at the buffer front, re-reference them to their valid
    mean, rebuild prefix sums and recompute every window sum exactly. Returns the new
    reference level (deg/h)."""
    off = length - w
    total = 0.0
    nv = 0
    for i in range(w):
        yraw[i] = yraw[off + i]
        vraw[i] = vraw[off + i]
        if vraw[i]:
            total += yraw[i]
            nv += 1
    ref = total / nv if nv > 0 else 0.0
    psum[0] = 0.0
    bad[0] = 0
    stream_append(yraw[:w].copy(), vraw[:w].copy(), yraw, vraw, psum, bad, 0, ref)
    for k in range(ms.shape[0]):
        m = ms[k]
        s = 0.0
        c = 0.0
        n = 0
        for j in range(w - 2 * m + 1):
            if bad[j + 2 * m] == bad[j]:
                t = ((psum[j + 2 * m] - psum[j + m]) - (psum[j + m] - psum[j])) / m
                s, err = _two_sum(s, t * t)
                c += err
                n += 1
        sum_s[k] = s
        sum_c[k] = c
        cnt[k] = n
    return ref
