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
def _compensated_sum(x, n):
    """Sum of x[:n] as (s, c) with s + c accurate to ~eps^2 relative to sum |x| (so a
    huge term that later leaves a window leaves no residue): four interleaved TwoSum
    chains for instruction-level parallelism, then combined."""
    s0 = s1 = s2 = s3 = 0.0
    c0 = c1 = c2 = c3 = 0.0
    n4 = n - n % 4
    for i in range(0, n4, 4):
        s0, r0 = _two_sum(s0, x[i])
        s1, r1 = _two_sum(s1, x[i + 1])
        s2, r2 = _two_sum(s2, x[i + 2])
        s3, r3 = _two_sum(s3, x[i + 3])
        c0 += r0
        c1 += r1
        c2 += r2
        c3 += r3
    for i in range(n4, n):
        s0, r0 = _two_sum(s0, x[i])
        c0 += r0
    s, r = _two_sum(s0, s1)
    c = c0 + c1 + c2 + c3 + r
    s, r = _two_sum(s, s2)
    c += r
    s, r = _two_sum(s, s3)
    return s, c + r


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


@njit(cache=True, inline="always")
def _sq_term(psum, bad, j, m):
    """Squared term of factor m starting at buffer position j, 0 when it spans a gap;
    and 1 or 0 for its validity."""
    t = ((psum[j + 2 * m] - psum[j + m]) - (psum[j + m] - psum[j])) / m
    ok = bad[j + 2 * m] == bad[j]
    return (t * t if ok else 0.0), (1 if ok else 0)


_TILE = 1024  # samples per tile of the streaming update: the deltas of 4 taus stay in L1


@njit(cache=True, inline="always")
def _tile_deltas(psum, bad, m, w, first, n, d, de, dn):
    """Per new sample at buffer positions first..first+n-1: d + de = (entering term)^2 -
    (leaving term)^2 exactly (TwoSum) and dn = change in valid-term count. Vectorisable
    fast path when no invalid sample touches the tile's terms; returns True when some dn
    may be non-zero."""
    inv = 1.0 / m
    a_in = first - 2 * m + 1
    a_out = first - w
    if bad[first + n] == bad[a_in] and bad[a_out + n - 1 + 2 * m] == bad[a_out]:
        # unit-stride slices indexed by a loop counter: no wrap-around checks, SIMD
        p0, p1, p2 = psum[a_in:a_in + n], psum[a_in + m:a_in + m + n], psum[a_in + 2 * m:a_in + 2 * m + n]
        q0, q1, q2 = psum[a_out:a_out + n], psum[a_out + m:a_out + m + n], psum[a_out + 2 * m:a_out + 2 * m + n]
        for i in range(n):
            t_in = ((p2[i] - p1[i]) - (p1[i] - p0[i])) * inv
            t_out = ((q2[i] - q1[i]) - (q1[i] - q0[i])) * inv
            d[i], de[i] = _two_sum(t_in * t_in, -(t_out * t_out))
            dn[i] = 0  # read when another tau of the group has gaps
        return False
    else:
        for i in range(n):
            x_in, v_in = _sq_term(psum, bad, a_in + i, m)
            x_out, v_out = _sq_term(psum, bad, a_out + i, m)
            d[i], de[i] = _two_sum(x_in, -x_out)
            dn[i] = v_in - v_out
        return True


@njit(cache=True)
def stream_update(first, n_new, w, ms, psum, bad, sum_s, sum_c, cnt, emit_pos, out_sums, out_counts):
    """Slide the window over buffer positions ``first .. first + n_new - 1`` (already
    appended; the buffer holds at least the ``w`` samples before ``first`` or starts at
    the record's first sample, position 0 then meaning absolute index 0). For every m the
    term ending at each new sample enters and the term starting at the sample that left
    leaves; the running sums are compensated (TwoSum). At the buffer positions
    ``emit_pos`` (increasing) the current sums and counts are written to the rows of
    ``out_sums``/``out_counts``. Steady state runs in tiles, 4 taus at a time: a
    vectorised pass for the term deltas, then 4 interleaved compensated sums, run
    branch-free between emission points."""
    nm = ms.shape[0]
    stop = first + n_new
    e_head = 0
    # head: the first window is still filling, terms only enter
    for k in range(nm):
        m = ms[k]
        e = 0
        p = first
        while p < stop and p < w:
            if p - 2 * m + 1 >= 0:
                x, v = _sq_term(psum, bad, p - 2 * m + 1, m)
                s, err = _two_sum(sum_s[k], x)
                sum_s[k] = s
                sum_c[k] += err
                cnt[k] += v
            if e < emit_pos.shape[0] and emit_pos[e] == p:
                out_sums[e, k] = sum_s[k] + sum_c[k]
                out_counts[e, k] = cnt[k]
                e += 1
            p += 1
        e_head = e
    start = max(first, w)
    d = np.empty((4, _TILE))
    de = np.empty((4, _TILE))
    dn = np.empty((4, _TILE), np.int64)
    e_tile = e_head
    for t0 in range(start, stop, _TILE):
        n = min(_TILE, stop - t0)
        e_end = e_tile
        while e_end < emit_pos.shape[0] and emit_pos[e_end] < t0 + n:
            e_end += 1
        for g in range(0, nm, 4):
            k0, k1, k2, k3 = g, min(g + 1, nm - 1), min(g + 2, nm - 1), min(g + 3, nm - 1)
            has_dn = _tile_deltas(psum, bad, ms[k0], w, t0, n, d[0], de[0], dn[0])
            has_dn |= _tile_deltas(psum, bad, ms[k1], w, t0, n, d[1], de[1], dn[1])
            has_dn |= _tile_deltas(psum, bad, ms[k2], w, t0, n, d[2], de[2], dn[2])
            has_dn |= _tile_deltas(psum, bad, ms[k3], w, t0, n, d[3], de[3], dn[3])
            s0, s1, s2, s3 = sum_s[k0], sum_s[k1], sum_s[k2], sum_s[k3]
            c0, c1, c2, c3 = sum_c[k0], sum_c[k1], sum_c[k2], sum_c[k3]
            n0, n1, n2, n3 = cnt[k0], cnt[k1], cnt[k2], cnt[k3]
            e = e_tile
            da, db, dc, dd = d[0], d[1], d[2], d[3]
            ea, eb, ec, ed = de[0], de[1], de[2], de[3]
            i0 = 0
            while i0 < n:
                # run up to the next emission point (or the tile end) without branches
                i1 = n if e >= e_end else min(n, emit_pos[e] - t0 + 1)
                for i in range(i0, i1):
                    s0, r0 = _two_sum(s0, da[i])
                    s1, r1 = _two_sum(s1, db[i])
                    s2, r2 = _two_sum(s2, dc[i])
                    s3, r3 = _two_sum(s3, dd[i])
                    c0 += r0 + ea[i]
                    c1 += r1 + eb[i]
                    c2 += r2 + ec[i]
                    c3 += r3 + ed[i]
                if has_dn:
                    for i in range(i0, i1):
                        n0 += dn[0, i]
                        n1 += dn[1, i]
                        n2 += dn[2, i]
                        n3 += dn[3, i]
                if i1 < n or (e < e_end and emit_pos[e] == t0 + n - 1):
                    out_sums[e, k0] = s0 + c0
                    out_sums[e, k1] = s1 + c1
                    out_sums[e, k2] = s2 + c2
                    out_sums[e, k3] = s3 + c3
                    out_counts[e, k0] = n0
                    out_counts[e, k1] = n1
                    out_counts[e, k2] = n2
                    out_counts[e, k3] = n3
                    e += 1
                i0 = i1
            # duplicated slots (k clipped to nm - 1) hold the same values: write in reverse
            sum_s[k3], sum_c[k3], cnt[k3] = s3, c3, n3
            sum_s[k2], sum_c[k2], cnt[k2] = s2, c2, n2
            sum_s[k1], sum_c[k1], cnt[k1] = s1, c1, n1
            sum_s[k0], sum_c[k0], cnt[k0] = s0, c0, n0
        e_tile = e_end


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
    d = np.empty(w)
    for k in range(ms.shape[0]):
        m = ms[k]
        nt = w - 2 * m + 1
        if bad[w] == bad[0]:
            p0, p1, p2 = psum[0:nt], psum[m:m + nt], psum[2 * m:2 * m + nt]
            inv = 1.0 / m
            for j in range(nt):
                t = ((p2[j] - p1[j]) - (p1[j] - p0[j])) * inv
                d[j] = t * t
            n = nt
        else:
            n = 0
            for j in range(nt):
                d[j], v = _sq_term(psum, bad, j, m)
                n += v
        sum_s[k], sum_c[k] = _compensated_sum(d, nt)
        cnt[k] = n
    return ref


@njit(cache=True)
def frame_stats(sums, counts, run, full, edf_gapless, f_lo, f_hi):
    """One pass over windows (rows) x taus: adev = sqrt(sum / (2 count)) (NaN without
    terms), bounds and EDF from the gap-free tables of the row's alpha run; returns
    (adev, lo, hi, edf, gapped) where ``gapped`` marks entries with fewer than ``full``
    terms, whose EDF and bounds the caller recomputes."""
    nt, nm = sums.shape
    adev = np.empty((nt, nm))
    lo = np.empty((nt, nm))
    hi = np.empty((nt, nm))
    edf = np.empty((nt, nm))
    gapped = np.zeros((nt, nm), np.bool_)
    for i in range(nt):
        r = run[i]
        for k in range(nm):
            n = counts[i, k]
            a = np.sqrt(max(sums[i, k], 0.0) / (2.0 * n)) if n > 0 else np.nan
            adev[i, k] = a
            lo[i, k] = a * f_lo[r, k]
            hi[i, k] = a * f_hi[r, k]
            edf[i, k] = edf_gapless[r, k]
            gapped[i, k] = n != full[k]
    return adev, lo, hi, edf, gapped
