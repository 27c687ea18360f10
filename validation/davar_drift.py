"""Numerical drift of the streaming DAVAR engine over a long run.

Streams >= 1e8 samples of a 1000 deg/h bias plus white rate noise, a slow bias random
walk, glitches of 1e6 deg/h and short gaps through a 2^16-sample window and compares the
last window the engine emits (it ends at the last sample) - ADEV and term counts - with
an exact batch recompute of the same samples. PASS when the largest relative difference
is <= 1e-9. ``--hop`` below 64 samples exercises the running-sum mode, from 64 up the
recorded-sum mode (see fogmon/davar/streaming.py).

    python validation/davar_drift.py [--samples 100000000] [--window 65536] [--hop 65536] [--seed 1]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from fogmon.davar.batch import oadev
from fogmon.davar.streaming import StreamingDadev



def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=100_000_000)
    ap.add_argument("--window", type=int, default=2**16)
    ap.add_argument("--hop", type=int, default=None, help="samples between windows (default: the window)")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
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
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
