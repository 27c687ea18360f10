"""Numba kernels of the Allan-variance engines.

Conventions: a *term* of averaging factor m starting at sample j is
``(sum y[j+m : j+2m] - sum y[j : j+m]) / m`` (deg/h), computed from prefix sums ``P`` of
``y - ref`` (``ref``: robust reference level, ``reference_level``; invalid samples
contribute 0). The prefix count ``bad`` holds 1 per invalid sample and _FLAG per sample
kept out of ``P``: a term whose span changes ``bad`` by 0 is a plain term, by a
multiple of _FLAG a term spanning out-of-sum samples, otherwise it spans a gap and is
not counted. Out-of-sum samples are

- *huge* (|rate| > CEILING_DPH or infinite): they enter no sum at all; a term spanning
  one is +inf (it is counted), so a window holding one reports ADEV = +inf and no window
  without it is touched;
- *large* (streaming only, |rate - ref| > LARGE_DPH): kept in a double-double side prefix
  (``bh``, ``bl``) read only by the terms spanning them, so the main prefix sums never
  carry their magnitude.

Sums are kept as a compensated pair (Knuth TwoSum: ``s`` plus the accumulated rounding
errors ``c``). The streaming engine has two modes (see fogmon/davar/streaming.py):
recorded cumulative sums (``stream_record``) and running window sums with a rigorous
rounding bound (``stream_update``, fogmon/davar/running_sums.py). Streaming kernels take the prefix arrays as one
tuple ``pre = (P, bad, bh, bl, hc)`` (``hc``: prefix count of huge samples).
"""
from __future__ import annotations

import numpy as np
from numba import types

from fogmon.jit import B1, BOOL, F1, F2, F8, I1, I2, I8, kernel

CEILING_DPH = 1e8
"""|rate| above this (deg/h, 27,800 deg/s: beyond any gyro) or infinite makes a sample
*huge*: it enters no sum and the Allan terms spanning it are +inf."""
LARGE_DPH = 65536.0
"""|rate - reference level| above this (deg/h) makes a sample *large* in the streaming
engine: kept out of the main prefix sums (double-double side prefix)."""
_FLAG = 1 << 32  # count unit of out-of-sum samples in ``bad`` and of huge-spanning terms in counts
_LOW = _FLAG - 1  # mask of the plain counts
_FAST = {"nsz", "arcp", "reassoc", "contract"}  # fastmath without "no inf" (terms may be +inf)


@kernel()
def _two_sum(s, x):
    """Return (s + x, rounding error of that addition)."""
    t = s + x
    bp = t - s
    return t, (s - (t - bp)) + (x - bp)


@kernel()
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


_PRE = types.Tuple((F1, I1, F1, F1, I1))  # the streaming prefix arrays ``pre``, see the module docstring
_REF_SAMPLES = 4096  # at most this many evenly spaced samples make the reference level


@kernel()
def heap_sort(v, n):
    """Sort v[:n] in place, ascending (no NaN). Plain loops: numba's np.sort and np.median
    cost a second or two of compile on the first run."""
    for i in range(n // 2 - 1, -1, -1):
        _sift_down(v, i, n)
    for end in range(n - 1, 0, -1):
        v[0], v[end] = v[end], v[0]
        _sift_down(v, 0, end)


@kernel(inline="always")
def _sift_down(v, root, end):
    while 2 * root + 1 < end:
        child = 2 * root + 1
        if child + 1 < end and v[child] < v[child + 1]:
            child += 1
        if not v[root] < v[child]:
            return
        v[root], v[child] = v[child], v[root]
        root = child


@kernel()
def median_of(v, n):
    """Median of v[:n] (no NaN; v is sorted in place), as numpy.median: the mean of the
    two middle values of an even count; NaN when n is 0."""
    if n == 0:
        return np.nan
    heap_sort(v, n)
    return v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2


@kernel()
def _median_valid(y, valid, step):
    """Median of every step-th sample that is valid and within CEILING_DPH; NaN if none."""
    buf = np.empty(y.shape[0] // step + 1)
    n = 0
    for i in range(0, y.shape[0], step):
        if valid[i] and abs(y[i]) <= CEILING_DPH:
            buf[n] = y[i]
            n += 1
    return median_of(buf, n)


@kernel((F1, B1))
def reference_level(y, valid):
    """Median (deg/h) of the valid samples within CEILING_DPH (of at most about
    _REF_SAMPLES evenly spaced ones), NaN without any: the level subtracted before the
    prefix sums. No single sample can move it far; it only has to be near the signal."""
    step = max(1, y.shape[0] // _REF_SAMPLES)
    ref = _median_valid(y, valid, step)
    return _median_valid(y, valid, 1) if ref != ref and step > 1 else ref


@kernel((F1, B1, F8))
def prefix_sums_dd(y, valid, ref):
    """Double-double prefix sums of ``y - ref`` over valid samples within CEILING_DPH
    (``hi``, ``lo``, n+1 each) and the prefix count ``bad`` (n+1): 1 per invalid sample,
    _FLAG per huge one (left out of the sums)."""
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
        if not valid[i]:
            b += 1
        elif not abs(y[i]) <= CEILING_DPH:
            b += _FLAG
        else:
            s, e = _two_sum(s, y[i] - ref)
            c += e
        hi[i + 1] = s
        lo[i + 1] = c
        bad[i + 1] = b
    return hi, lo, bad


@kernel()
def _term_dd(hi, lo, j, m):
    a = j + m
    b = j + 2 * m
    return (((hi[b] - hi[a]) - (hi[a] - hi[j])) + ((lo[b] - lo[a]) - (lo[a] - lo[j]))) / m


@kernel()
def _renorm(s, c):
    """The compensated pair (s, c) with c folded into s, so that |c| <= ulp(s) / 2 (exact:
    Fast2Sum, |c| <= |s|). A cumulative sum adds TwoSum errors to c unnormalised (one
    dependent add per segment) and is renormalised once per tile, so c never carries more
    than the roundings of one tile's segments."""
    u = s + c
    return u, c - (u - s)


@kernel()
def _dd_sub(s, c, bs, bc):
    """Double-double (s, c) - (bs, bc), renormalised."""
    t, r = _two_sum(s, -bs)
    r += c - bc
    u = t + r
    return u, r - (u - t)


@kernel((F1, B1, F1, B1, _PRE, I8, F8))
def stream_append(y, valid, yraw, vraw, pre, length, ref):
    """Append samples to the linear buffer: raw values, validity and the prefix arrays
    ``pre`` (main sums of ``y - ref``, counts, large-sample side sums, huge counts; see
    the module docstring). The side arrays are only written once the buffer holds an
    out-of-sum sample (they are 0 before it: zeroed on re-anchoring). Returns the number
    of large samples appended."""
    psum, bad, bh, bl, hc = pre
    s = psum[length]
    b = bad[length]
    sh = bh[length]
    sl = bl[length]
    h = hc[length]
    n_large = 0
    for i in range(y.shape[0]):
        p = length + i
        yraw[p] = y[i]
        vraw[p] = valid[i]
        if not valid[i]:
            b += 1
        elif not abs(y[i]) <= CEILING_DPH:
            b += _FLAG
            h += 1
        else:
            d = y[i] - ref
            if abs(d) > LARGE_DPH:
                b += _FLAG
                d, dl = _two_sum(y[i], -ref)  # y - ref exactly: ref may be far off (a glitch)
                sh, e = _two_sum(sh, d)
                sl += e + dl
                n_large += 1
            else:
                s += d
        psum[p + 1] = s
        bad[p + 1] = b
        if b >= _FLAG:  # side arrays are written from the buffer's first out-of-sum sample on (else 0)
            bh[p + 1] = sh
            bl[p + 1] = sl
            hc[p + 1] = h
    return n_large


@kernel()
def _sq_term(pre, j, m):
    """(squared term of factor m starting at buffer position j, 1 if it is counted, 1 if
    it spans a huge sample). A term spanning a gap is (0, 0, 0), one spanning a huge
    sample (0, 1, 1); one spanning large samples adds their side sums. A plain term is
    bit-identical to the vectorised passes (``* (1 / m)``), so that a term entering one
    way and leaving the other cancels exactly."""
    psum, bad, bh, bl, hc = pre
    a = j + m
    b = j + 2 * m
    inv = 1.0 / m
    t = (psum[b] - psum[a]) - (psum[a] - psum[j])
    d = bad[b] - bad[j]
    if d == 0:
        t *= inv
        return t * t, 1, 0
    if d & _LOW:
        return 0.0, 0, 0
    if hc[b] != hc[j]:
        return 0.0, 1, 1
    t = (t + _side(bh[j], bh[a], bh[b], bl[j], bl[a], bl[b])) * inv
    return t * t, 1, 0


@kernel()
def _side(h0, h1, h2, l0, l1, l2):
    """Second difference (h2 - h1) - (h1 - h0) of the double-double side sums, formed in
    double-double: exact whatever magnitude they hold (0 when they do not change)."""
    s1, e1 = _two_sum(h2, -h1)
    s2, e2 = _two_sum(h1, -h0)
    s, e = _two_sum(s1, -s2)
    return s + (e + ((e1 - e2) + ((l2 - l1) - (l1 - l0))))


@kernel()
def _no_gap_no_huge(pre, a, b):
    """Buffer positions a..b-1 hold no invalid and no huge sample (large ones may be)."""
    return (pre[1][b] - pre[1][a]) & _LOW == 0 and pre[4][b] == pre[4][a]


@kernel()
def _large_terms(pre, a0, n, m, x):
    """Squared terms of factor m starting at a0 .. a0+n-1 into x[:n] when none spans a
    gap or a huge sample: main and side second differences, branch-free (a plain term
    comes out bit-identical to ``_sq_term``'s, its side difference being exactly 0)."""
    psum, bh, bl = pre[0], pre[2], pre[3]
    inv = 1.0 / m
    p0, p1, p2 = psum[a0:a0 + n], psum[a0 + m:a0 + m + n], psum[a0 + 2 * m:a0 + 2 * m + n]
    h0, h1, h2 = bh[a0:a0 + n], bh[a0 + m:a0 + m + n], bh[a0 + 2 * m:a0 + 2 * m + n]
    l0, l1, l2 = bl[a0:a0 + n], bl[a0 + m:a0 + m + n], bl[a0 + 2 * m:a0 + 2 * m + n]
    for i in range(n):
        t = (((p2[i] - p1[i]) - (p1[i] - p0[i])) + _side(h0[i], h1[i], h2[i], l0[i], l1[i], l2[i])) * inv
        x[i] = t * t


_TILE = 1024  # samples per tile of the streaming update: 4 taus' term arrays stay in L1
_EPS = 2.0**-52


@kernel()
def _batch_terms(hi, lo, bad, j0, n, m, x, v):
    """Squared terms of factor m starting at samples j0 .. j0+n-1 into x[:n] from the
    double-double prefix sums (+inf where a term spans a huge sample, 0 where it spans a
    gap). When some term is not plain their validity (1.0 / 0.0) goes to v[:n] and True
    is returned; else v is left unwritten (vectorised path)."""
    inv = 1.0 / m
    if bad[j0 + n - 1 + 2 * m] == bad[j0]:
        h0, h1, h2 = hi[j0:j0 + n], hi[j0 + m:j0 + m + n], hi[j0 + 2 * m:j0 + 2 * m + n]
        l0, l1, l2 = lo[j0:j0 + n], lo[j0 + m:j0 + m + n], lo[j0 + 2 * m:j0 + 2 * m + n]
        for i in range(n):
            t = (((h2[i] - h1[i]) - (h1[i] - h0[i])) + ((l2[i] - l1[i]) - (l1[i] - l0[i]))) * inv
            x[i] = t * t
        return False
    for i in range(n):
        j = j0 + i
        d = bad[j + 2 * m] - bad[j]
        if d == 0:
            t = _term_dd(hi, lo, j, m)
            x[i] = t * t
            v[i] = 1.0
        elif d & _LOW == 0:
            x[i] = np.inf
            v[i] = 1.0
        else:
            x[i] = 0.0
            v[i] = 0.0
    return True


@kernel(fastmath=_FAST)
def _range_sum(x, i0, i1):
    """Sum of x[i0:i1] in any order (SIMD; +inf when it holds a +inf). The loop runs over
    a slice from 0: indexing x from a variable start defeats vectorisation (numba's
    negative-index check)."""
    u = x[i0:i1]
    s = 0.0
    for i in range(u.shape[0]):
        s += u[i]
    return s


@kernel()
def _open_windows(starts, w):
    """The ring size of the records of windows begun and not yet ended: a power of two
    (slot = window & (size - 1)) above the most windows of ``w`` samples starting at
    ``starts`` (non-decreasing) that hold one sample."""
    most = 0
    p = 0
    for q in range(starts.shape[0]):
        while starts[p] + w < starts[q]:
            p += 1
        most = max(most, q - p + 1)
    size = 1
    while size <= most:
        size *= 2
    return size


@kernel((F1, F1, I1, I1, I1, I8))
def window_sums(hi, lo, bad, ms, starts, w):
    """Sums of squared valid terms (+inf for a window holding a huge sample) and
    valid-term counts (T x M) for windows of ``w`` samples starting at ``starts``
    (non-decreasing), from the double-double prefix sums ``hi``, ``lo`` and counts ``bad``
    of ``prefix_sums_dd``: O(N) per m for all windows. Per tile of _TILE terms and per m
    (tiles outside, taus inside, so the prefix sums a tile reads come from the cache for
    every tau) the squared terms are formed vectorised and summed (SIMD) between the cut
    points (window starts and ends); the segment sums enter a compensated cumulative sum
    per m (TwoSum, ``_renorm`` per tile), recorded at each window's start (a ring of
    ``_open_windows`` slots), and a window's sum is the cumulative sum at its end minus
    that record. A segment lies inside every window it overlaps, so a window carries only
    the roundings of its own segments (<= _TILE eps of its sum) and per segment <= 2
    _TILE eps^2 of the cumulative sum: a large glitch leaves no residue in the windows not
    holding it."""
    nt = starts.shape[0]
    nm = ms.shape[0]
    sums = np.zeros((nt, nm))
    counts = np.zeros((nt, nm), np.int64)
    if nt == 0:
        return sums, counts
    ring = _open_windows(starts, w)
    s_at = np.empty((nm, ring))
    c_at = np.empty((nm, ring))
    n_at = np.empty((nm, ring), np.int64)
    h_at = np.empty((nm, ring), np.int64)
    # per m: cumulative sum (s, c), valid terms, segments holding a term spanning a huge
    # sample, next window to record (qa) and to emit (qb)
    cum_s = np.zeros(nm)
    cum_c = np.zeros(nm)
    cum_n = np.zeros(nm, np.int64)
    cum_h = np.zeros(nm, np.int64)
    qa_k = np.zeros(nm, np.int64)
    qb_k = np.zeros(nm, np.int64)
    x = np.empty(_TILE)
    v = np.empty(_TILE)
    big = np.iinfo(np.int64).max
    j_last = starts[0]  # one past the last term any m needs
    for k in range(nm):
        if 2 * ms[k] <= w:
            j_last = max(j_last, starts[nt - 1] + w - 2 * ms[k] + 1)
    for t0 in range(starts[0], j_last, _TILE):
        for k in range(nm):
            m = ms[k]
            qb = qb_k[k]
            if 2 * m > w or qb == nt:
                continue
            span = w - 2 * m + 1  # terms per window
            j_end = starts[nt - 1] + span  # one past the last term needed
            n = min(_TILE, j_end - t0)
            last = t0 + n == j_end
            s, c, cnt, nh, qa = cum_s[k], cum_c[k], cum_n[k], cum_h[k], qa_k[k]
            gaps = _batch_terms(hi, lo, bad, t0, n, m, x, v)
            pos = 0
            while True:
                b = min(starts[qa] if qa < nt else big, starts[qb] + span if qb < nt else big)
                p = min(b - t0, n)
                if p > pos:  # the segment of terms t0 + pos .. t0 + p - 1
                    seg = _range_sum(x, pos, p)
                    if seg == np.inf:
                        nh += 1
                    else:
                        s, r = _two_sum(s, seg)
                        c += r
                    cnt += int(_range_sum(v, pos, p)) if gaps else p - pos
                    pos = p
                if b - t0 > n or (b - t0 == n and not last):
                    break
                while qa < nt and starts[qa] == b:
                    slot = qa & (ring - 1)
                    s_at[k, slot] = s
                    c_at[k, slot] = c
                    n_at[k, slot] = cnt
                    h_at[k, slot] = nh
                    qa += 1
                while qb < nt and starts[qb] + span == b:
                    slot = qb & (ring - 1)
                    if nh > h_at[k, slot]:
                        sums[qb, k] = np.inf
                    else:
                        d, e = _two_sum(s, -s_at[k, slot])
                        sums[qb, k] = d + (e + (c - c_at[k, slot]))
                    counts[qb, k] = cnt - n_at[k, slot]
                    qb += 1
                if qb == nt:
                    break
            s, c = _renorm(s, c)
            cum_s[k], cum_c[k], cum_n[k], cum_h[k], qa_k[k], qb_k[k] = s, c, cnt, nh, qa, qb
    return sums, counts


@kernel()
def window_sum(pre, start, w, m, scratch, exact):
    """Recompute for the window of ``w`` samples from buffer position ``start``:
    (s, c, encoded count, bound) of the squared valid terms of factor m (count: valid
    terms + _FLAG x huge-spanning ones, which add 0 to s) and a bound of the rounding in
    s + c, (deg/h)^2. ``exact``: TwoSum for every term (bound ~ n eps^2 s, so even a
    huge term that leaves later leaves no residue); else SIMD sums of 256-term blocks
    (non-negative terms: bound 256 eps s) added by TwoSum. No terms (2m > w): zeros."""
    nt = w - 2 * m + 1
    if nt <= 0:
        return 0.0, 0.0, 0, 0.0
    psum, bad = pre[0], pre[1]
    if bad[start + w] == bad[start]:
        p0, p1, p2 = psum[start:start + nt], psum[start + m:start + m + nt], psum[start + 2 * m:start + 2 * m + nt]
        inv = 1.0 / m
        for j in range(nt):
            t = ((p2[j] - p1[j]) - (p1[j] - p0[j])) * inv
            scratch[j] = t * t
        n = nt
    elif _no_gap_no_huge(pre, start, start + w):
        _large_terms(pre, start, nt, m, scratch)
        n = nt
    else:
        n = 0
        for j in range(nt):
            scratch[j], v, h = _sq_term(pre, start + j, m)
            n += v + _FLAG * h
    if exact:
        s, c = _compensated_sum(scratch, nt)
        return s, c, n, nt * _EPS * _EPS * (s + c)
    s = 0.0
    c = 0.0
    for i0 in range(0, nt, 256):
        s, r = _two_sum(s, _range_sum(scratch, i0, min(i0 + 256, nt)))
        c += r
    return s, c, n, 256.0 * _EPS * (s + c)


@kernel((F1, B1, _PRE, I8, I8, I1, F1, F1, I1, F1, BOOL, F2, F2, F8))
def stream_reanchor(yraw, vraw, pre, length, keep, ms, sum_s, sum_c, cnt, err, recorded, rec_s, rec_c, ref):
    """Keep the last ``keep`` samples at the buffer front, re-reference them to their
    reference level (``ref`` if they have none) and rebuild the prefix arrays. Running
    sums (not ``recorded``): recompute every window sum exactly over the kept samples.
    Recorded sums: re-base each cumulative sum on its current value (the records follow),
    so that the squared terms that came before (a large glitch) cost no precision later.
    Returns the new reference level (deg/h)."""
    off = length - keep
    for i in range(keep):
        yraw[i] = yraw[off + i]
        vraw[i] = vraw[off + i]
    new_ref = reference_level(yraw[:keep], vraw[:keep])
    if new_ref == new_ref:
        ref = new_ref
    psum, bad, bh, bl, hc = pre
    if bad[length] >= _FLAG:  # side arrays were written: zero them
        bh[:length + 1] = 0.0
        bl[:length + 1] = 0.0
        hc[:length + 1] = 0
    psum[0] = 0.0
    bad[0] = 0
    stream_append(yraw[:keep].copy(), vraw[:keep].copy(), yraw, vraw, pre, 0, ref)
    if recorded:
        for k in range(ms.shape[0]):
            for q in range(rec_s.shape[1]):
                rec_s[k, q], rec_c[k, q] = _dd_sub(rec_s[k, q], rec_c[k, q], sum_s[k], sum_c[k])
            sum_s[k] = 0.0
            sum_c[k] = 0.0
    else:
        scratch = np.empty(keep)
        for k in range(ms.shape[0]):
            sum_s[k], sum_c[k], cnt[k], err[k] = window_sum(pre, 0, keep, ms[k], scratch, False)
    return ref


@kernel((_PRE, I8, I8, I1))
def window_sums_exact(pre, start, n, ms):
    """Sums of squared valid terms (deg/h)^2 (+inf when one spans a huge sample) and
    valid-term counts, per m, of the ``n`` samples from buffer position ``start``,
    TwoSum-exact."""
    nm = ms.shape[0]
    sums = np.zeros(nm)
    counts = np.zeros(nm, np.int64)
    scratch = np.empty(n)
    for k in range(nm):
        if 2 * ms[k] <= n:
            s, c, nn, _ = window_sum(pre, start, n, ms[k], scratch, True)
            sums[k] = s + c if nn < _FLAG else np.inf
            counts[k] = nn & _LOW
    return sums, counts


@kernel()
def _entering_terms(pre, a0, n, m, x, v):
    """Squared terms of factor m starting at buffer positions a0 .. a0+n-1 into x[:n] (0
    where a term spans a gap, +inf where it spans a huge sample). When some term is not
    plain their validity (1.0 / 0.0) goes to v[:n] and True is returned; else v is left
    unwritten (vectorised path)."""
    psum, bad = pre[0], pre[1]
    inv = 1.0 / m
    if bad[a0 + n - 1 + 2 * m] == bad[a0]:
        p0, p1, p2 = psum[a0:a0 + n], psum[a0 + m:a0 + m + n], psum[a0 + 2 * m:a0 + 2 * m + n]
        for i in range(n):
            t = ((p2[i] - p1[i]) - (p1[i] - p0[i])) * inv
            x[i] = t * t
        return False
    if _no_gap_no_huge(pre, a0, a0 + n - 1 + 2 * m):
        _large_terms(pre, a0, n, m, x)  # large samples only: every term counts
        return False
    for i in range(n):
        x[i], ok, h = _sq_term(pre, a0 + i, m)
        if h:
            x[i] = np.inf
        v[i] = ok
    return True


@kernel(fastmath=_FAST)
def _segment_sums(x, bounds, n_seg, out):
    """out[c] = sum of x[bounds[c] : bounds[c + 1]] for c < n_seg, in any order (SIMD;
    +inf when the segment holds a +inf)."""
    for c in range(n_seg):
        u = x[bounds[c]:bounds[c + 1]]
        s = 0.0
        for i in range(u.shape[0]):
            s += u[i]
        out[c] = s


@kernel((I8, I8, I8, I8, I8, I1, _PRE, F1, F1, I1, I1, F2, F2, I2, I2, I8, F2, I2))
def stream_record(first, n_new, base, w, hop, ms, pre, cum_s, cum_c, cum_n, cum_h, rec_s, rec_c, rec_n, rec_h,
                  k_row0, out_sums, out_counts):
    """Recorded-sums update over buffer positions ``first .. first + n_new - 1`` (already
    appended; buffer position 0 is absolute sample ``base``). Per m only the term ending
    at each new sample is computed: it enters the cumulative sum of squared terms
    (compensated cum_s + cum_c, ``_renorm`` per tile; valid-term count cum_n; a term spanning a huge sample
    is +inf and enters only cum_h, the count of segments holding one). Window k (absolute samples
    k hop .. w - 1 + k hop) starts at term k hop, so the cumulative sum of the terms
    before it is recorded (ring slot k mod R of rec_*) when that term's predecessor
    enters, and at the window's last sample its sum is the cumulative sum minus that
    record: windows never recompute and no term is computed twice. Rounding: each
    window carries only the roundings of the SIMD segment sums inside it (<= _TILE eps
    of its sum) and per segment <= 2 _TILE eps^2 of the cumulative sum since the last re-base (a large glitch
    that has left leaves no residue), however long the run. A window whose segments
    hold a +inf term has sum +inf. Windows emitted here are ``k_row0 + row`` (rows of
    out_sums/out_counts)."""
    nm = ms.shape[0]
    ring = rec_s.shape[1]
    stop = first + n_new
    x = np.empty(_TILE)
    v = np.empty(_TILE)
    bounds = np.empty(2 * _TILE + 2, np.int64)
    s_rec = np.empty(2 * _TILE + 1, np.int64)  # per cut: ring slot of the record taken there, or -1
    s_out = np.empty(2 * _TILE + 1, np.int64)  # per cut: ring slot of the window emitted there, or -1
    r_out = np.empty(2 * _TILE + 1, np.int64)  # its output row
    seg = np.empty(2 * _TILE + 1)
    cnt = np.empty(2 * _TILE + 1)
    for t0 in range(first, stop, _TILE):
        n = min(_TILE, stop - t0)
        a_abs = base + t0  # absolute index of the tile's first sample
        for k in range(nm):
            m = ms[k]
            # cut points: after sample k_r hop + 2m - 2 record window k_r's start, after
            # sample w - 1 + k_e hop emit window k_e
            kr = max(0, -(-(a_abs - 2 * m + 2) // hop))
            pr = kr * hop + 2 * m - 2 - a_abs
            ke = max(0, -(-(a_abs - w + 1) // hop))
            pe = w - 1 + ke * hop - a_abs
            sr = kr % ring  # ring slots advance by one per window: no division per cut
            se = ke % ring
            n_cut = 0
            bounds[0] = 0
            while min(pr, pe) < n:
                p = min(pr, pe)
                bounds[n_cut + 1] = p + 1
                s_rec[n_cut] = sr if pr == p else -1
                s_out[n_cut] = se if pe == p else -1
                r_out[n_cut] = ke - k_row0
                n_cut += 1
                if pr == p:
                    pr += hop
                    sr = sr + 1 if sr + 1 < ring else 0
                if pe == p:
                    ke += 1
                    pe += hop
                    se = se + 1 if se + 1 < ring else 0
            bounds[n_cut + 1] = n
            # the terms ending at the tile's samples; none before the record's first term
            i0 = min(n, max(0, 2 * m - 1 - a_abs))
            gaps = False
            if i0 < n:
                gaps = _entering_terms(pre, t0 + i0 - 2 * m + 1, n - i0, m, x[i0:], v[i0:])
            if i0 > 0:
                x[:i0] = 0.0
                if not gaps:
                    v[i0:n] = 1.0
                v[:i0] = 0.0
                gaps = True
            _segment_sums(x, bounds, n_cut + 1, seg)
            if gaps:
                _segment_sums(v, bounds, n_cut + 1, cnt)
            s, c, nn, nh = cum_s[k], cum_c[k], cum_n[k], cum_h[k]
            for j in range(n_cut + 1):
                if seg[j] == np.inf:
                    nh += 1
                else:
                    s, r = _two_sum(s, seg[j])
                    c += r
                nn += int(cnt[j]) if gaps else bounds[j + 1] - bounds[j]
                if j == n_cut:
                    break
                if s_rec[j] >= 0:
                    slot = s_rec[j]
                    rec_s[k, slot] = s
                    rec_c[k, slot] = c
                    rec_n[k, slot] = nn
                    rec_h[k, slot] = nh
                if s_out[j] >= 0:
                    slot = s_out[j]
                    d, e = _two_sum(s, -rec_s[k, slot])
                    row = r_out[j]
                    out_sums[row, k] = d + (e + (c - rec_c[k, slot])) if nh == rec_h[k, slot] else np.inf
                    out_counts[row, k] = nn - rec_n[k, slot]
            s, c = _renorm(s, c)
            cum_s[k], cum_c[k], cum_n[k], cum_h[k] = s, c, nn, nh
