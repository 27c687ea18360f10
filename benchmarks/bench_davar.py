"""Throughput of the DAVAR engines, measured against allantools in the same run.

Prints samples/s of: the streaming engine (46 log-spaced taus, 2^16-sample window) at hop
1 (running sums) and hop 1024 (recorded sums), both the engine alone (``StreamingDadev.advance``: window sums and counts)
and with full frames (``push``: ADEV, chi-square bounds, EDF per window); the engine on a
rate swinging +-1e6 deg/h (every sample "large": the side-prefix path); the batch engine
(``dadev``, hop 1024); recomputing ``allantools.oadev`` on every window at hop 1024; the
ratios; and the resident memory growth over 1e7 streamed samples. Every figure is the
best of ``--repeat`` runs, interleaved, so that load from other processes on a shared
machine biases none of them.

    python benchmarks/bench_davar.py [--samples 4000000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import time

import allantools
import numpy as np

from fogmon.davar.batch import dadev
from fogmon.davar.streaming import StreamingDadev

WINDOW = 2**16
BLOCK = 2**16


def log_taus(count: int, m_max: int) -> np.ndarray:
    """``count`` distinct log-spaced averaging factors from 1 to m_max."""
    for k in range(count, 4 * count):
        m = np.unique(np.round(np.geomspace(1, m_max, k)).astype(np.int64))
        if len(m) >= count:
            return m[np.round(np.linspace(0, len(m) - 1, count)).astype(int)]
    raise ValueError("no such grid")


def rss_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def rate_per_s(fn, n_samples: int) -> float:
    t = time.perf_counter()
    fn()
    return n_samples / (time.perf_counter() - t)


def stream(y, m, hop, frames: bool) -> float:
    eng = StreamingDadev(1.0, WINDOW, taus=m.astype(float), hop_s=hop, alpha=0)
    eng.advance(y[:WINDOW])  # fill the first window, compile
    feed = eng.push if frames else eng.advance

    def run():
        for i in range(WINDOW, len(y), BLOCK):
            feed(y[i:i + BLOCK])
    return rate_per_s(run, len(y) - WINDOW)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=4_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    m = log_taus(46, WINDOW // 4)
    rng = np.random.default_rng(0)
    y = 1000.0 + rng.normal(size=args.samples)
    swing = 1e6 * np.sin(2 * np.pi * np.arange(args.samples) / 20000.0) + rng.normal(size=args.samples)
    StreamingDadev(1.0, 4096, taus=8, hop_s=1).push(y[:20000])  # compile all kernels once
    dadev(y[:20000], 1.0, 4096.0, 1024.0, taus=8, alpha=0)

    def allantools_per_window(windows=8):
        t = time.perf_counter()
        for k in range(windows):
            allantools.oadev(y[k * 1024:k * 1024 + WINDOW], rate=1.0, data_type="freq", taus=m.astype(float))
        return 1024 * windows / (time.perf_counter() - t)

    runs = {
        "stream engine, hop 1": lambda: stream(y, m, 1, frames=False),
        "stream engine, hop 1024": lambda: stream(y, m, 1024, frames=False),
        "stream frames, hop 1024": lambda: stream(y, m, 1024, frames=True),
        "stream engine, +-1e6 swing, hop 1024": lambda: stream(swing, m, 1024, frames=False),
        "stream engine, +-1e6 swing, hop 1": lambda: stream(swing[:WINDOW + 8 * BLOCK], m, 1, frames=False),
        "stream frames, hop 1": lambda: stream(y[:WINDOW + 8 * BLOCK], m, 1, frames=True),
        "batch dadev, hop 1024": lambda: rate_per_s(
            lambda: dadev(y, 1.0, WINDOW, 1024, taus=m.astype(float), alpha=0), len(y)),
        "allantools per window, hop 1024": allantools_per_window,
    }
    res = dict.fromkeys(runs, 0.0)
    for _ in range(args.repeat):
        for name, run in runs.items():
            res[name] = max(res[name], run())

    print(f"{len(m)} log-spaced taus (m = 1 .. {m[-1]}), window {WINDOW} samples, {args.samples:.3g} samples, "
          f"1 core per engine, best of {args.repeat}")
    ref = res["allantools per window, hop 1024"]
    for name, v in res.items():
        print(f"{name:38s} {v / 1e6:10.3f} M samples/s   {v / ref:10.1f} x allantools recompute")
    print(f"hop 1 / hop 1024 cost ratio (engine): "
          f"{res['stream engine, hop 1024'] / res['stream engine, hop 1']:.2f}")

    eng = StreamingDadev(1.0, WINDOW, taus=m.astype(float), hop_s=1024, alpha=0)
    eng.push(y[:2 * WINDOW])
    before = rss_mb()
    total, i = 0, 0
    while total < 10_000_000:
        eng.push(y[i:i + BLOCK])
        total += BLOCK
        i = (i + BLOCK) % (len(y) - BLOCK)
    after = rss_mb()
    print(f"RSS before {before:.1f} MB, after {total:.3g} more streamed samples {after:.1f} MB: "
          f"growth {after - before:+.1f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
