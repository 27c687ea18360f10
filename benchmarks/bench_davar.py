"""Throughput of the DAVAR paths users call, beside references measured in the same run.

46 log-spaced taus, 2^16-sample window, white rate noise on a 1000 deg/h bias. Every
figure is samples per CPU second (the machine may be loaded: CPU time, and ratios to
references measured in the same run), the best of ``--repeat`` interleaved repeats.

Rows (issue 13's table), each beside its reference:
- ``StreamingDadev.push`` default (noise type from the quick fit), hop 1024 and 64,
  blocks of 8192 -- vs push with a fixed alpha, the engine alone (``advance``) and
  ``allantools.oadev`` recomputed on every window;
- push one sample per call (hop 1024) -- vs allantools' pure-Python ``oadev_realtime``
  (``add_frequency`` per sample, the same 46 taus);
- push at hop 1 (a window per sample), fixed alpha, 32 blocks of 8192 -- vs the engine alone,
  and with every window's adev read, or every window's interval (``DadevResult`` forms
  adev from the windows' sums, and lo/hi from adev, when first read), and the engine
  alone at hop 1 vs at hop 32 (the same running sums, 1/32 of the windows emitted:
  what the emission of a window per sample costs);
- batch ``fogmon.dadev`` (default alpha) at hop 1024 and 64, ``fogmon.oadev`` -- vs a
  plain numpy prefix-sum DAVAR of the same windows;
- the engine on a rate swinging +-1e6 deg/h (every sample "large": the side-prefix path)
  at hop 1024 and hop 1 -- vs the engine on the static rate.
Then PASS/FAIL lines for the targets (issue 13's; issue 33's hop-1 push against the engine at
hop 1024) and the resident-memory growth over 1e7 pushed samples.

    python benchmarks/bench_davar.py [--samples 2000000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import time

import allantools
import numpy as np
from allantools.realtime import oadev_realtime

from fogmon.davar.batch import dadev, oadev
from fogmon.davar.streaming import StreamingDadev

WINDOW = 2**16
BLOCK = 8192
N_TAUS = 46


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


def per_cpu_s(fn, n_samples: int) -> float:
    """Samples per CPU second of ``fn()`` processing ``n_samples``."""
    t = time.process_time()
    fn()
    return n_samples / max(time.process_time() - t, 1e-9)


def stream(y, m, hop, alpha, feed="push", block=BLOCK, read_bounds=False, read_adev=False) -> float:
    """Samples/s of pushing y after its first window (which fills the engine) in blocks
    (``read_adev``: and reading every window's adev, ``read_bounds``: every window's
    interval (adev included); both formed when first read)."""
    eng = StreamingDadev(1.0, WINDOW, taus=m.astype(float), hop_s=hop, alpha=alpha)
    eng.push(y[:WINDOW])
    fn = getattr(eng, feed)

    def run():
        for i in range(WINDOW, len(y), block):
            out = fn(y[i:i + block])
            if read_adev:
                _ = out.adev_dph
            if read_bounds:
                _ = out.lo_dph, out.hi_dph
    return per_cpu_s(run, len(y) - WINDOW)


def numpy_dadev(y, w, hop, m) -> np.ndarray:
    """Reference: plain numpy DAVAR (T x M) from one prefix sum of y - mean and, per m,
    a cumulative sum of squared overlapping terms differenced at the window starts."""
    p = np.concatenate([[0.0], np.cumsum(y - y.mean())])
    starts = np.arange(0, len(y) - w + 1, hop)
    out = np.empty((len(starts), len(m)))
    for k, mk in enumerate(m):
        t = (p[2 * mk:] - 2.0 * p[mk:-mk] + p[:-2 * mk]) / mk
        c = np.concatenate([[0.0], np.cumsum(t * t)])
        span = w - 2 * mk + 1
        out[:, k] = (c[starts + span] - c[starts]) / (2.0 * span)
    return np.sqrt(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=2_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    m = log_taus(N_TAUS, WINDOW // 4)
    rng = np.random.default_rng(0)
    y = 1000.0 + rng.normal(size=args.samples)
    swing = 1e6 * np.sin(2 * np.pi * np.arange(args.samples) / 20000.0) + rng.normal(size=args.samples)
    n_one = 50_000  # samples pushed one per call
    n_hop1 = WINDOW + 32 * BLOCK  # 32 blocks: the first ones fault their result memory in
    n_rt = 2000  # samples into allantools' realtime class (pure Python, slow)
    # compile / load every kernel once, and check the numpy reference computes the same thing
    ref = numpy_dadev(y[:4 * WINDOW], WINDOW, 1024, m)
    got = dadev(y[:4 * WINDOW], 1.0, WINDOW, 1024, taus=m.astype(float)).adev_dph
    assert np.allclose(got, ref, rtol=1e-9), "numpy reference disagrees with fogmon.dadev"
    StreamingDadev(1.0, 4096, taus=8, hop_s=1).push(y[:20000])
    StreamingDadev(1.0, 4096, taus=8, hop_s=1024).push(y[:20000])

    def one_sample():
        eng = StreamingDadev(1.0, WINDOW, taus=m.astype(float), hop_s=1024)
        eng.push(y[:WINDOW])
        seg = y[WINDOW:WINDOW + n_one]

        def run():
            for i in range(n_one):
                eng.push(seg[i:i + 1])
        return per_cpu_s(run, n_one)

    def realtime():
        dev = oadev_realtime(afs=[int(k) for k in m], tau0=1.0)

        def run():
            for v in y[:n_rt]:
                dev.add_frequency(v)
        return per_cpu_s(run, n_rt)

    def allantools_per_window(windows=4):
        def run():
            for k in range(windows):
                allantools.oadev(y[k * 1024:k * 1024 + WINDOW], rate=1.0, data_type="freq", taus=m.astype(float))
        return per_cpu_s(run, 1024 * windows)

    def batch(fn, *a, n=None, **kw):
        return lambda: per_cpu_s(lambda: fn(*a, **kw), len(y) if n is None else n)

    runs = {
        "push default alpha, hop 1024": lambda: stream(y, m, 1024, None),
        "push default alpha, hop 64": lambda: stream(y, m, 64, None),
        "push alpha=0, hop 1024": lambda: stream(y, m, 1024, 0),
        "push alpha=0, hop 64": lambda: stream(y, m, 64, 0),
        "engine alone (advance), hop 1024": lambda: stream(y, m, 1024, 0, "advance"),
        "engine alone (advance), hop 64": lambda: stream(y, m, 64, 0, "advance"),
        "allantools.oadev per window, hop 1024": allantools_per_window,
        "push one sample per call, hop 1024": one_sample,
        "allantools oadev_realtime, per sample": realtime,
        "push alpha=0, hop 1": lambda: stream(y[:n_hop1], m, 1, 0),
        "push alpha=0, hop 1, every adev read": lambda: stream(y[:n_hop1], m, 1, 0, read_adev=True),
        "push alpha=0, hop 1, every bound read": lambda: stream(y[:n_hop1], m, 1, 0, read_bounds=True),
        "engine alone (advance), hop 1": lambda: stream(y[:n_hop1], m, 1, 0, "advance"),
        "engine alone (advance), hop 32": lambda: stream(y[:n_hop1], m, 32, 0, "advance"),
        "engine, +-1e6 deg/h swing, hop 1024": lambda: stream(swing, m, 1024, 0, "advance"),
        "engine, +-1e6 deg/h swing, hop 1": lambda: stream(swing[:n_hop1], m, 1, 0, "advance"),
        "batch dadev default, hop 1024": batch(dadev, y, 1.0, WINDOW, 1024, taus=m.astype(float)),
        "batch dadev default, hop 64": batch(dadev, y[:len(y) // 2], 1.0, WINDOW, 64, taus=m.astype(float),
                                             n=len(y) // 2),
        "batch oadev default": batch(oadev, y, 1.0, taus=m.astype(float)),
        "numpy prefix-sum dadev, hop 1024": batch(numpy_dadev, y, WINDOW, 1024, m),
        "numpy prefix-sum dadev, hop 64": batch(numpy_dadev, y[:len(y) // 2], WINDOW, 64, m, n=len(y) // 2),
        "numpy prefix-sum oadev": batch(numpy_dadev, y, len(y), 1, m),
    }
    res = dict.fromkeys(runs, 0.0)
    for _ in range(args.repeat):
        for name, run in runs.items():
            res[name] = max(res[name], run())

    print(f"{N_TAUS} log-spaced taus (m = 1 .. {m[-1]}), window {WINDOW} samples, blocks of {BLOCK}, "
          f"{args.samples:.3g} samples; samples per CPU second, best of {args.repeat} interleaved repeats")

    def row(name, ref_name):
        v, r = res[name], res[ref_name]
        print(f"  {name:40s} {v / 1e6:9.3f} M/s   {v / r:8.2f} x {ref_name}")

    def block(title, rows):
        print(title)
        for name, ref_name in rows:
            row(name, ref_name)

    at = "allantools.oadev per window, hop 1024"
    block("1. default push (alpha=None)", [
        ("push default alpha, hop 1024", "push alpha=0, hop 1024"),
        ("push default alpha, hop 1024", at),
        ("push default alpha, hop 64", "push alpha=0, hop 64"),
        ("push alpha=0, hop 1024", "engine alone (advance), hop 1024"),
        ("engine alone (advance), hop 1024", at)])
    block("2. one sample per call", [("push one sample per call, hop 1024", "allantools oadev_realtime, per sample")])
    block("3. hop 1", [("push alpha=0, hop 1", "engine alone (advance), hop 1"),
                       ("push alpha=0, hop 1, every adev read", "push alpha=0, hop 1"),
                       ("push alpha=0, hop 1, every bound read", "push alpha=0, hop 1"),
                       ("engine alone (advance), hop 1", "engine alone (advance), hop 32")])
    block("engine on large samples", [
        ("engine, +-1e6 deg/h swing, hop 1024", "engine alone (advance), hop 1024"),
        ("engine, +-1e6 deg/h swing, hop 1", "engine alone (advance), hop 1")])
    block("4. batch", [
        ("batch dadev default, hop 1024", "numpy prefix-sum dadev, hop 1024"),
        ("batch dadev default, hop 64", "numpy prefix-sum dadev, hop 64"),
        ("batch oadev default", "numpy prefix-sum oadev")])

    def target(ok, text):
        print(f"{'PASS' if ok else 'FAIL'}  {text}")

    print("targets (issues 13, 33):")
    for hop in (1024, 64):
        v = res[f"push default alpha, hop {hop}"]
        target(v >= 10e6, f"default push at hop {hop} >= 10 M samples/s: {v / 1e6:.2f} M/s")
    v, r = res["push one sample per call, hop 1024"], res["allantools oadev_realtime, per sample"]
    target(v >= 100e3 and v >= 10 * r, f"one-sample push >= 100 k samples/s and >= 10x oadev_realtime: "
                                       f"{v / 1e3:.0f} k/s, {v / r:.1f}x")
    v = res["push alpha=0, hop 1"]
    target(v >= 5e6, f"hop-1 push >= 5 M samples/s: {v / 1e6:.2f} M/s (adev and intervals formed when read; "
                     f"reading every window's adev: {res['push alpha=0, hop 1, every adev read'] / 1e6:.2f} M/s, "
                     f"interval: {res['push alpha=0, hop 1, every bound read'] / 1e6:.2f} M/s)")
    r = v / res["engine alone (advance), hop 1024"]
    r_read = res["push alpha=0, hop 1, every adev read"] / res["engine alone (advance), hop 1024"]
    target(r >= 0.25, f"hop-1 push >= 0.25x the engine (advance, hop 1024; issue 33): {r:.3f}x "
                      f"(reading every window's adev: {r_read:.3f}x)")
    for name, ref_name in [("batch dadev default, hop 1024", "numpy prefix-sum dadev, hop 1024"),
                           ("batch dadev default, hop 64", "numpy prefix-sum dadev, hop 64"),
                           ("batch oadev default", "numpy prefix-sum oadev")]:
        ratio = res[name] / res[ref_name]
        target(ratio >= 3.0, f"{name} >= 3x the numpy prefix-sum reference: {ratio:.2f}x")

    eng = StreamingDadev(1.0, WINDOW, taus=m.astype(float), hop_s=1024)
    eng.push(y[:2 * WINDOW])
    before = rss_mb()
    total, i = 0, 0
    while total < 10_000_000:
        eng.push(y[i:i + BLOCK])
        total += BLOCK
        i = (i + BLOCK) % (len(y) - BLOCK)
    after = rss_mb()
    print(f"RSS before {before:.1f} MB, after {total:.3g} more pushed samples {after:.1f} MB: "
          f"growth {after - before:+.1f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
