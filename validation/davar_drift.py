"""Numerical drift of the streaming DAVAR engine over a long run.

Streams >= 1e8 samples of a 1000 deg/h bias plus white rate noise, a slow bias random
walk, glitches of 1e6 deg/h and short gaps through a 2^16-sample window and compares the
final window's ADEV and term counts with an exact batch recompute of the same samples.
PASS when the largest relative difference is <= 1e-9.

    python validation/davar_drift.py [--samples 100000000] [--window 65536] [--seed 1]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from fogmon.davar.batch import oadev
from fogmon.davar.streaming import StreamingDadev

BLOCK = 2**20


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=100_000_000)
    ap.add_argument("--window", type=int, default=2**16)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    engine = StreamingDadev(1.0, args.window, taus="octave", hop_s=args.window)
    tail = np.empty(0)
    tail_valid = np.empty(0, dtype=bool)
    walk = 0.0
    t0 = time.perf_counter()
    for start in range(0, args.samples, BLOCK):
        n = min(BLOCK, args.samples - start)
        bias = walk + np.cumsum(rng.normal(size=n)) * 1e-3  # slow bias random walk, deg/h
        walk = bias[-1]
        y = 1000.0 + bias + rng.normal(size=n)
        valid = np.ones(n, dtype=bool)
        for g in rng.integers(0, n - 20, size=3):
            y[g] += 1e6  # glitch
            valid[g + 5:g + 5 + int(rng.integers(1, 15))] = False  # gap
        if start + n == args.samples:  # a glitch that has just left the final window, a gap inside it
            y[n - args.window - 10] += 1e6
            valid[n - args.window // 2:n - args.window // 2 + 7] = False
        engine.push(y, valid)
        tail = np.concatenate([tail, y])[-args.window:]
        tail_valid = np.concatenate([tail_valid, valid])[-args.window:]
    dt = time.perf_counter() - t0
    cur = engine.current()
    ref = oadev(tail, 1.0, taus="octave", valid=tail_valid)
    same_counts = np.array_equal(cur.n_terms, ref.n_terms)
    rel = np.max(np.abs(cur.adev_dph / ref.adev_dph - 1))
    print(f"streamed {engine.n_pushed:.3g} samples in {dt:.1f} s ({engine.n_pushed / dt / 1e6:.2f} M samples/s "
          f"incl. generation), window {args.window}, {len(cur.m)} octave taus, bias 1000 deg/h")
    print(f"{'m':>6s} {'stream adev':>14s} {'exact adev':>14s} {'rel diff':>10s} {'terms':>7s}")
    for k in range(len(cur.m)):
        print(f"{cur.m[k]:6d} {cur.adev_dph[k]:14.9g} {ref.adev_dph[k]:14.9g} "
              f"{cur.adev_dph[k] / ref.adev_dph[k] - 1:10.2e} {cur.n_terms[k]:7d}")
    ok = rel <= 1e-9 and same_counts and engine.n_pushed >= args.samples
    print(f"max relative difference {rel:.2e} (limit 1e-9), term counts equal: {same_counts}")
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
