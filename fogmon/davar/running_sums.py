"""Numba kernels of the streaming engine's running window sums (``stream_update``: hops
below 64, fogmon/davar/streaming.py): per tile of 4 taus x _TILE samples the entering and
leaving squared terms, running sums with a rigorous rounding bound, and the exact
fall-back where the bound does not hold. The term and prefix-sum conventions are those
of fogmon/davar/kernels.py.
"""
from __future__ import annotations

import numpy as np

from fogmon.davar.kernels import (
    _EPS,
    _FLAG,
    _LOW,
    _PRE,
    _TILE,
    _large_terms,
    _no_gap_no_huge,
    _sq_term,
    _two_sum,
    window_sum,
)
from fogmon.jit import F1, F2, I1, I2, I8, kernel

_BOUND_RTOL = 1e-11  # largest rounding, relative to a window sum, the plain path may accumulate


@kernel()
def _tile_terms(pre, m, w, first, n, x_in, x_out, dn):
    """For new samples at buffer positions first..first+n-1: squared entering and
    leaving terms (0 when not plain) and the change in encoded valid-term count (valid
    terms + _FLAG x huge-spanning terms). Vectorisable fast path when only plain terms
    touch the tile (then ``dn`` is left unwritten and False returned); True when dn was
    written."""
    psum, bad = pre[0], pre[1]
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
            x_in[i] = t_in * t_in
            x_out[i] = t_out * t_out
        return False  # dn not written: the caller zeroes it if another tau of the group has gaps
    if _no_gap_no_huge(pre, a_in, first + n) and _no_gap_no_huge(pre, a_out, a_out + n - 1 + 2 * m):
        _large_terms(pre, a_in, n, m, x_in)  # large samples only: every term counts
        _large_terms(pre, a_out, n, m, x_out)
        return False
    for i in range(n):
        x_in[i], v_in, h_in = _sq_term(pre, a_in + i, m)
        x_out[i], v_out, h_out = _sq_term(pre, a_out + i, m)
        dn[i] = (v_in - v_out) + _FLAG * (h_in - h_out)
    return True


@kernel()
def _tile_diffs(pre, m, w, first, n, x_in, x_out, x_d, x_a, dn):
    """``_tile_terms`` as the differences ``x_d`` = entering - leaving and the sums ``x_a``
    = entering + leaving of the squared terms (what the plain sums read), the same values
    as formed from its ``x_in`` and ``x_out`` (scratch here; not written on the fast
    path). Returns as ``_tile_terms``."""
    psum, bad = pre[0], pre[1]
    a_in = first - 2 * m + 1
    a_out = first - w
    if bad[first + n] == bad[a_in] and bad[a_out + n - 1 + 2 * m] == bad[a_out]:
        inv = 1.0 / m
        p0, p1, p2 = psum[a_in:a_in + n], psum[a_in + m:a_in + m + n], psum[a_in + 2 * m:a_in + 2 * m + n]
        q0, q1, q2 = psum[a_out:a_out + n], psum[a_out + m:a_out + m + n], psum[a_out + 2 * m:a_out + 2 * m + n]
        for i in range(n):
            t_in = ((p2[i] - p1[i]) - (p1[i] - p0[i])) * inv
            t_out = ((q2[i] - q1[i]) - (q1[i] - q0[i])) * inv
            s_in = t_in * t_in
            s_out = t_out * t_out
            x_d[i] = s_in - s_out
            x_a[i] = s_in + s_out
        return False
    wrote = _tile_terms(pre, m, w, first, n, x_in, x_out, dn)
    for i in range(n):
        x_d[i] = x_in[i] - x_out[i]
        x_a[i] = x_in[i] + x_out[i]
    return wrote


@kernel(fastmath=True)
def _tile_totals(x_d, x_a, n):
    """(sum of x_d, sum of x_a) over n samples, in any order (SIMD)."""
    d = 0.0
    a = 0.0
    for i in range(n):
        d += x_d[i]
        a += x_a[i]
    return d, a


@kernel()
def _put(out_sums, out_counts, e, k, s, n):
    """Write window row e, tau k from its sum s and encoded count n: +inf when a term
    spans a huge sample; the count of valid terms."""
    out_sums[e, k] = s if n < _FLAG else np.inf
    out_counts[e, k] = n & _LOW


@kernel((I8, I8, I8, I1, _PRE, F1, F1, I1, F1, I1, F2, I2))
def stream_update(first, n_new, w, ms, pre, sum_s, sum_c, cnt, err, emit_pos, out_sums, out_counts):
    """Running-sum update (hops below streaming.RECORD_MIN_HOP). Slide the window over
    buffer positions ``first .. first + n_new - 1`` (already appended; the buffer holds at
    least the ``w`` samples before ``first`` or starts at the record's first sample,
    position 0 then meaning absolute index 0). For every m the
    term ending at each new sample enters and the term starting at the sample that left
    leaves. At the buffer positions ``emit_pos`` (increasing) the current sums and counts
    are written to the rows of ``out_sums``/``out_counts``. ``cnt`` holds encoded counts
    (valid terms + _FLAG x huge-spanning terms, which add 0 to the sums). Returns
    ``fixed``: no count changed after the first emitted row; then only row 0 of
    ``out_counts`` is sure to be written, and it holds every row's counts (hop 1 without
    gaps writes no count per window).

    Steady state runs in tiles of 4 taus x _TILE samples: a vectorised pass for the
    squared terms and a SIMD sum of the tile's change, added to the compensated window
    sum (s, c). ``err`` holds per m a rigorous bound of the rounding accumulated by those
    plain sums; a tile that would take it above _BOUND_RTOL of the window sum (a large
    glitch leaving, a window drained by gaps) first recomputes its taus' window sums
    exactly (O(window)) and is then accumulated term by term with TwoSum."""
    nm = ms.shape[0]
    stop = first + n_new
    e_head = 0
    # head: the first window is still filling, terms only enter (exact TwoSum)
    for k in range(nm):
        m = ms[k]
        e = 0
        p = first
        while p < stop and p < w:
            if p - 2 * m + 1 >= 0:
                x, v, h = _sq_term(pre, p - 2 * m + 1, m)
                s, r = _two_sum(sum_s[k], x)
                sum_s[k] = s
                sum_c[k] += r
                cnt[k] += v + _FLAG * h
            if e < emit_pos.shape[0] and emit_pos[e] == p:
                _put(out_sums, out_counts, e, k, sum_s[k] + sum_c[k], cnt[k])
                e += 1
            p += 1
        e_head = e
    start = max(first, w)
    xi = np.empty((4, _TILE))
    xo = np.empty((4, _TILE))
    xd = np.empty((4, _TILE))  # entering - leaving squared terms
    xa = np.empty((4, _TILE))  # entering + leaving
    dn = np.empty((4, _TILE), np.int64)
    # the emitted windows' sums are written straight into their rows of ``out_sums``;
    # per tile sample, the encoded counts per tau of the window it emits
    n_at = np.empty((_TILE, nm), np.int64)
    tot = np.empty(4)
    low = np.empty(4)
    grow = np.empty(4)
    bnd = np.empty(4)
    ks = np.empty(4, np.int64)
    wrote = np.zeros(4, np.bool_)
    scratch = np.empty(w)
    e_tile = e_head
    fixed = True  # no count changed since the first emitted row: dense tiles write no counts
    for t0 in range(start, stop, _TILE):
        n = min(_TILE, stop - t0)
        e_end = e_tile
        while e_end < emit_pos.shape[0] and emit_pos[e_end] < t0 + n:
            e_end += 1
        # every sample from the tile's first emission to its last emits (hop 1): the
        # rows are scanned together (see _scan_plain)
        dense = e_end > e_tile and emit_pos[e_end - 1] - emit_pos[e_tile] == e_end - 1 - e_tile
        for g in range(0, nm, 4):
            has_dn = False
            plain = True
            for j in range(4):
                k = min(g + j, nm - 1)  # slots past the last tau repeat it
                ks[j] = k
                wrote[j] = _tile_diffs(pre, ms[k], w, t0, n, xi[j], xo[j], xd[j], xa[j], dn[j])
                has_dn |= wrote[j]
                tot[j], mag = _tile_totals(xd[j], xa[j], n)
                # rounding of the squares' differences, the tile sum and the emission scan
                grow[j] = 3.0 * n * _EPS * mag
                # below every window sum of the tile: the leaving terms sum to (mag - tot) / 2
                low[j] = sum_s[k] + sum_c[k] - 0.5 * (mag - tot[j]) - grow[j]
                plain &= _within(err[k] + grow[j], sum_s[k] + sum_c[k] + tot[j])
            if fixed and has_dn:  # counts change from here on
                fixed = _unfix(out_counts, e_head, e_tile, cnt, n_at, g, n)
            # dn is read by the emission scans when a tau has count changes (and by the
            # exact path, see below): zero the unwritten rows
            for j in range(4 if has_dn else 0):
                if not wrote[j]:
                    dn[j, :n] = 0
            if plain and (has_dn or e_end > e_tile):  # the bound must also hold at every emitted window
                for j in range(4):  # (_scan_plain's chains start at the compensation c: its roundings)
                    bnd[j] = err[ks[j]] + grow[j] + n * _EPS * abs(sum_c[ks[j]])
                if dense:
                    # the least emitted sum is needed only when the bound does not hold at ``low``
                    track = not (_within(bnd[0], low[0]) and _within(bnd[1], low[1]) and _within(bnd[2], low[2])
                                 and _within(bnd[3], low[3]))
                    plain = _scan_plain(xd, dn, has_dn, fixed, track, n, t0, e_tile, e_end, emit_pos, ks, bnd,
                                        sum_s, sum_c, cnt, out_sums[e_tile:e_end], n_at)
                else:
                    plain = _emit_plain(xd, dn, has_dn, n, t0, e_tile, e_end, emit_pos, ks, bnd, sum_s, sum_c,
                                        cnt, out_sums, out_counts)
            if plain:
                for j in range(4):
                    if j == 0 or ks[j] != ks[j - 1]:
                        s, r = _two_sum(sum_s[ks[j]], tot[j])
                        sum_s[ks[j]] = s
                        sum_c[ks[j]] += r
                        err[ks[j]] += grow[j]
            else:
                for j in range(4):
                    if j == 0 or ks[j] != ks[j - 1]:
                        k = ks[j]
                        s, c, n_k, err[k] = window_sum(pre, t0 - w, w, ms[k], scratch, True)
                        if fixed and n_k != cnt[k]:
                            fixed = _unfix(out_counts, e_head, e_tile, cnt, n_at, g, n)
                        sum_s[k], sum_c[k], cnt[k] = s, c, n_k
                for j in range(4):  # the entering and leaving terms apart (TwoSum of their difference)
                    _tile_terms(pre, ms[ks[j]], w, t0, n, xi[j], xo[j], dn[j])
                if not has_dn:
                    dn[:, :n] = 0
                _accumulate_exact(xi, xo, dn, n, t0, e_tile, e_end, emit_pos, ks, sum_s, sum_c, cnt, out_sums, n_at)
                if not dense:
                    _emit_rows(n_at, g, ks[3] + 1, t0, e_tile, e_end, emit_pos, out_sums, out_counts, False,
                               cnt)
        huge = False
        for k in range(nm):
            huge |= cnt[k] >= _FLAG
        if dense and (huge or not fixed):  # the rows' +inf and counts (a dense tile wrote neither)
            _emit_rows(n_at, 0, nm, t0, e_tile, e_end, emit_pos, out_sums, out_counts, fixed, cnt)
        e_tile = e_end
    if fixed and e_tile > 0:
        _unfix(out_counts, 0, 1, cnt, n_at, 0, 0)
    return fixed


@kernel()
def _unfix(out_counts, e0, e1, cnt, n_at, k1, n):
    """Write the counts ``cnt`` (encoded) to rows e0 .. e1 - 1, which were emitted while
    no count changed (and so without them), and to the tile's ``n_at[:n, :k1]`` (the
    taus scanned before the change, which wrote none). Returns False."""
    for e in range(e0, e1):
        c_row = out_counts[e]
        for k in range(c_row.shape[0]):
            c_row[k] = cnt[k] & _LOW
    for i in range(n):
        for k in range(k1):
            n_at[i, k] = cnt[k]
    return False


@kernel()
def _emit_plain(xd, dn, has_dn, n, t0, e0, e1, emit_pos, ks, bnd, sum_s, sum_c, cnt, out_sums, out_counts):
    """Write the windows emitted in a plain tile (running sums from the tile's start) and
    advance the valid-term counts over the tile. Returns False, changing no state, when
    an emitted window's sum is too small for the rounding bound ``bnd`` (per slot) of
    the plain sums (a huge term left inside the tile): the caller redoes the tile exactly."""
    k0, k1, k2, k3 = ks[0], ks[1], ks[2], ks[3]
    s0, s1, s2, s3 = sum_s[k0], sum_s[k1], sum_s[k2], sum_s[k3]
    c0, c1, c2, c3 = sum_c[k0], sum_c[k1], sum_c[k2], sum_c[k3]
    n0, n1, n2, n3 = cnt[k0], cnt[k1], cnt[k2], cnt[k3]
    p0 = p1 = p2 = p3 = 0.0
    i0 = 0
    for e in range(e0, e1):
        i1 = emit_pos[e] - t0 + 1
        for i in range(i0, i1):
            p0 += xd[0, i]
            p1 += xd[1, i]
            p2 += xd[2, i]
            p3 += xd[3, i]
            if has_dn:
                n0 += dn[0, i]
                n1 += dn[1, i]
                n2 += dn[2, i]
                n3 += dn[3, i]
        w0, w1, w2, w3 = s0 + (c0 + p0), s1 + (c1 + p1), s2 + (c2 + p2), s3 + (c3 + p3)
        if not (_within(bnd[0], w0) and _within(bnd[1], w1) and _within(bnd[2], w2) and _within(bnd[3], w3)):
            return False
        _put(out_sums, out_counts, e, k0, w0, n0)
        _put(out_sums, out_counts, e, k1, w1, n1)
        _put(out_sums, out_counts, e, k2, w2, n2)
        _put(out_sums, out_counts, e, k3, w3, n3)
        i0 = i1
    if has_dn:
        for i in range(i0, n):
            n0 += dn[0, i]
            n1 += dn[1, i]
            n2 += dn[2, i]
            n3 += dn[3, i]
    # slots past the last tau repeat it with the same values
    cnt[k3], cnt[k2], cnt[k1], cnt[k0] = n3, n2, n1, n0
    return True


@kernel()
def _scan_plain(xd, dn, has_dn, fixed, track, n, t0, e0, e1, emit_pos, ks, bnd, sum_s, sum_c, cnt, rows, n_at):
    """``_emit_plain`` for a tile in which every sample from the first emission (e0 <
    e1) to the last emits (hop 1): the running sums at these samples go to their
    windows' ``rows`` (rows e0 .. e1 - 1 of the output; +inf is set by ``_emit_rows``),
    the counts to ``n_at`` (none while the counts are ``fixed`` and ``dn`` is zero; see
    ``_emit_rows``), by a branch-free scan of four independent chains, which also
    track the least emitted sum per slot for the bound check when ``track`` (else the
    bound is known to hold at a lower bound of every window sum of the tile)."""
    k0, k1, k2, k3 = ks[0], ks[1], ks[2], ks[3]
    s0, s1, s2, s3 = sum_s[k0], sum_s[k1], sum_s[k2], sum_s[k3]
    c0, c1, c2, c3 = sum_c[k0], sum_c[k1], sum_c[k2], sum_c[k3]
    n0, n1, n2, n3 = cnt[k0], cnt[k1], cnt[k2], cnt[k3]
    # the chains start at the compensations: a window's sum is s + (c + its terms' changes)
    p0, p1, p2, p3 = c0, c1, c2, c3
    i0 = emit_pos[e0] - t0
    i1 = emit_pos[e1 - 1] - t0 + 1
    for i in range(i0):
        p0 += xd[0, i]
        p1 += xd[1, i]
        p2 += xd[2, i]
        p3 += xd[3, i]
    # slices: a loop counter from 0 indexes them without wrap-around checks
    x0, x1, x2, x3 = xd[0, i0:i1], xd[1, i0:i1], xd[2, i0:i1], xd[3, i0:i1]
    m0 = m1 = m2 = m3 = np.inf
    for i in range(i1 - i0):
        p0 += x0[i]
        p1 += x1[i]
        p2 += x2[i]
        p3 += x3[i]
        w0, w1, w2, w3 = s0 + p0, s1 + p1, s2 + p2, s3 + p3
        row = rows[i]
        row[k0], row[k1], row[k2], row[k3] = w0, w1, w2, w3
        if track:
            m0, m1, m2, m3 = min(m0, w0), min(m1, w1), min(m2, w2), min(m3, w3)
    if not (_within(bnd[0], m0) and _within(bnd[1], m1) and _within(bnd[2], m2) and _within(bnd[3], m3)):
        return False
    if has_dn:
        for i in range(n):
            n0 += dn[0, i]
            n1 += dn[1, i]
            n2 += dn[2, i]
            n3 += dn[3, i]
            n_at[i, k0], n_at[i, k1], n_at[i, k2], n_at[i, k3] = n0, n1, n2, n3
    elif not fixed:
        for i in range(i0, i1):
            n_at[i, k0], n_at[i, k1], n_at[i, k2], n_at[i, k3] = n0, n1, n2, n3
    # slots past the last tau repeat it with the same values
    cnt[k3], cnt[k2], cnt[k1], cnt[k0] = n3, n2, n1, n0
    return True


@kernel()
def _emit_rows(n_at, k0, k1, t0, e0, e1, emit_pos, out_sums, out_counts, fixed, cnt):
    """Complete the rows of ``out_sums``/``out_counts`` of the windows emitted in a tile,
    taus k0 .. k1 - 1 (all of them: a whole row at a time, where writing one tau's
    column of many rows would cost a cache line per value), from the encoded counts
    ``n_at`` (per tau at the emitting sample's tile position): +inf for the sums (already
    in the rows) where a term spans a huge sample, and the counts of valid terms.
    ``fixed``: every count is ``cnt`` (encoded), and none is written."""
    c_fix = cnt[k0:k1]
    for e in range(e0, e1):
        i = emit_pos[e] - t0
        n_i, s_row, c_row = n_at[i, k0:k1], out_sums[e, k0:k1], out_counts[e, k0:k1]
        if fixed:
            for k in range(k1 - k0):
                if c_fix[k] >= _FLAG:
                    s_row[k] = np.inf
        else:
            for k in range(k1 - k0):
                n = n_i[k]
                if n >= _FLAG:
                    s_row[k] = np.inf
                c_row[k] = n & _LOW


@kernel()
def _within(bound, window_sum):
    """A rounding bound small enough for a window sum (deg/h)^2."""
    return bound == 0.0 or bound <= _BOUND_RTOL * window_sum


@kernel()
def _accumulate_exact(xi, xo, dn, n, t0, e0, e1, emit_pos, ks, sum_s, sum_c, cnt, out_sums, n_at):
    """Term-by-term TwoSum accumulation of a tile, the emitted windows' sums into their
    rows of ``out_sums`` (+inf is set by ``_emit_rows``), their encoded counts into ``n_at``."""
    for j in range(4):
        if j > 0 and ks[j] == ks[j - 1]:
            continue
        k = ks[j]
        s = sum_s[k]
        c = sum_c[k]
        n_ = cnt[k]
        e = e0
        for i in range(n):
            d, de = _two_sum(xi[j, i], -xo[j, i])
            s, r = _two_sum(s, d)
            c += r + de
            n_ += dn[j, i]
            if e < e1 and emit_pos[e] == t0 + i:
                out_sums[e, k] = s + c
                n_at[i, k] = n_
                e += 1
        sum_s[k] = s
        sum_c[k] = c
        cnt[k] = n_
