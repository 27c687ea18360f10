"""Numerical drift of the streaming DAVAR engine over a long run, and single huge samples.

Drift: streams >= 1e8 samples of a 1000 deg/h bias plus white rate noise, a slow bias
random walk, glitches of 1e6 deg/h, samples of 1e300 deg/h and short gaps through a
2^16-sample window and compares the last window the engine emits (it ends at the last
sample) - ADEV and term counts - with an exact batch recompute of the same samples.
PASS when the largest relative difference is <= 1e-9. ``--hop`` below 64 samples
exercises the running-sum mode, from 64 up the recorded-sum mode (see
fogmon/davar/streaming.py).

Huge samples: one sample of 1e30, 1e160, 1e300, inf, the largest float, -1e300 or 3e7
deg/h at the first sample, mid-record and near the end, streamed in blocks of 1 and 8192
(hops 1 and 16: running sums; 64 and window / 4: recorded sums) and through the batch
dadev: every window that does not hold it must equal the same window of the record
without it to 1e-12 relative (and the same term counts); windows holding it must be
+inf at m = 1 (|value| > 1e8 deg/h) or finite (3e7), never NaN where the record
without it has terms.

    python validation/davar_drift.py [--samples 100000000] [--window 65536] [--hop 65536] [--seed 1]
    python validation/davar_drift.py --huge-only
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from fogmon.davar.batch import dadev, oadev
from fogmon.davar.kernels import CEILING_DPH
from fogmon.davar.streaming import StreamingDadev

HUGE_VALUES = (1e30, 1e160, 1e300, np.inf, np.finfo(float).max, -1e300, 3e7)


def _stream(y, w, hop, block):
    eng = StreamingDadev(1.0, w, taus="octave", hop_s=hop, alpha=0, reanchor=w)
    out = [eng.advance(y[i:i + block]) for i in range(0, len(y), block)]
    ends, sums, counts = (np.concatenate(x) for x in zip(*out, strict=True))
    with np.errstate(invalid="ignore", divide="ignore"):
        return ends, np.sqrt(sums / (2.0 * counts)), counts


def _batch(y, w, hop, block):
    d = dadev(y, 1.0, w, hop, alpha=0)
    return d.end_index, d.adev_dph, d.n_terms


def huge_samples(seed: int, n: int = 12000, w: int = 2048) -> bool:
    """The huge-sample table; True when every case passes."""
    rng = np.random.default_rng(seed)
    clean = 1000.0 + rng.normal(size=n) * 0.3 + np.cumsum(rng.normal(size=n)) * 0.002
    positions = (0, n // 2 + 7, n - 9)
    print(f"single huge samples: {n} samples, window {w}, positions {positions}, limit 1e-12")
    print(f"{'engine':>28s} {'value':>10s} {'max rel diff outside':>21s} {'holding it':>11s} {'verdict':>8s}")
    ok_all = True
    for name, fn, hop, block in [("stream running hop 1", _stream, 1, 1), ("stream running hop 1", _stream, 1, 8192),
                                 ("stream running hop 16", _stream, 16, 8192),
                                 ("stream recorded hop 64", _stream, 64, 1),
                                 ("stream recorded hop 64", _stream, 64, 8192),
                                 ("stream recorded hop w/4", _stream, w // 4, 8192),
                                 ("batch hop 1", _batch, 1, 0), ("batch hop w/4", _batch, w // 4, 0)]:
        label = f"{name}" + (f", blocks {block}" if block else "")
        ends, ref, ref_counts = fn(clean, w, hop, block)
        for value in HUGE_VALUES:
            worst, inside_ok = 0.0, True
            for pos in positions:
                y = clean.copy()
                y[pos] = value
                e, adev, counts = fn(y, w, hop, block)
                holds = (e - w + 1 <= pos) & (pos <= e)
                same = np.array_equal(e, ends) and np.array_equal(counts, ref_counts) and np.array_equal(
                    np.isnan(adev), np.isnan(ref))
                with np.errstate(invalid="ignore"):
                    rel = np.nanmax(np.abs(adev[~holds] / ref[~holds] - 1), initial=0.0)
                worst = max(worst, rel if same else np.inf)
                inside = adev[holds]
                inside_ok &= bool(np.all(inside[:, 0] == np.inf) if abs(value) > CEILING_DPH else
                                  np.all(np.isfinite(inside) | np.isnan(ref[holds])))
            ok = worst <= 1e-12 and inside_ok
            ok_all &= ok
            inside_txt = ("+inf" if abs(value) > CEILING_DPH else "finite") if inside_ok else "WRONG"
            print(f"{label:>36s} {value:10.3g} {worst:21.2e} {inside_txt:>11s} {'PASS' if ok else 'FAIL':>8s}")
    print("huge samples: " + ("PASS" if ok_all else "FAIL"))
    return ok_all



def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=100_000_000)
    ap.add_argument("--window", type=int, default=2**16)
    ap.add_argument("--hop", type=int, default=None, help="samples between windows (default: the window)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--huge-only", action="store_true", help="only the single-huge-sample table")
    args = ap.parse_args(argv)
    huge_ok = huge_samples(args.seed)
    if args.huge_only:
        return 0 if huge_ok else 1
    w = args.window
    hop = args.hop or w
    block = 2 * w
    total = -(-args.samples // block) * block  # whole blocks: with hop dividing w, the last sample ends a window
    rng = np.random.default_rng(args.seed)
    engine = StreamingDadev(1.0, w, taus="octave", hop_s=hop, alpha=0)
    tail = np.empty(0)
    tail_valid = np.empty(0, dtype=bool)
    walk = 0.0
    t0 = time.perf_counter()
    for start in range(0, total, block):
        n = block
        bias = walk + np.cumsum(rng.normal(size=n)) * 1e-3  # slow bias random walk, deg/h
        walk = bias[-1]
        y = 1000.0 + bias + rng.normal(size=n)
        valid = np.ones(n, dtype=bool)
        last = start + n == total
        for g in rng.integers(0, n - w - 20 if last else n - 20, size=3):
            y[g] += 1e6  # glitch
            y[g + 3] = 1e300  # a huge sample
            valid[g + 5:g + 5 + int(rng.integers(1, 15))] = False  # gap
        if last:  # a glitch that has just left the final window (no other inside it), a gap inside it
            y[n - w - 10] += 1e6
            valid[n - w // 2:n - w // 2 + 7] = False
        ends, sums, counts = engine.advance(y, valid)
        tail = np.concatenate([tail, y])[-w:]
        tail_valid = np.concatenate([tail_valid, valid])[-w:]
    dt = time.perf_counter() - t0
    assert ends[-1] == engine.n_pushed - 1
    adev = np.sqrt(sums[-1] / (2.0 * counts[-1]))
    ref = oadev(tail, 1.0, taus="octave", valid=tail_valid)
    same_counts = np.array_equal(counts[-1], ref.n_terms)
    rel = np.max(np.abs(adev / ref.adev_dph - 1))
    print(f"streamed {engine.n_pushed:.3g} samples in {dt:.1f} s ({engine.n_pushed / dt / 1e6:.2f} M samples/s "
          f"incl. generation), window {w}, hop {hop}, {len(ref.m)} octave taus, bias 1000 deg/h")
    print(f"{'m':>6s} {'stream adev':>14s} {'exact adev':>14s} {'rel diff':>10s} {'terms':>7s}")
    for k in range(len(ref.m)):
        print(f"{ref.m[k]:6d} {adev[k]:14.9g} {ref.adev_dph[k]:14.9g} "
              f"{adev[k] / ref.adev_dph[k] - 1:10.2e} {counts[-1][k]:7d}")
    ok = rel <= 1e-9 and same_counts and engine.n_pushed >= args.samples
    print(f"max relative difference {rel:.2e} (limit 1e-9), term counts equal: {same_counts}")
    print("drift: " + ("PASS" if ok else "FAIL"))
    ok &= huge_ok
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
