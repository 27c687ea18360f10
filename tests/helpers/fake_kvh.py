"""A fake KVH DSP-1760 (binary format A, 1000 Hz) on a pseudo-terminal, for the monitor
tests, benchmarks/bench_pipeline.py and validation/faults_live.py:
``python tests/helpers/fake_kvh.py [SECONDS]`` prints the device path (the pty's slave
side) on stdout and sends frames at the device's pace (the frames due every 10 ms, at
most 2 ms late) until SECONDS have passed or it is killed;
``python tests/helpers/fake_kvh.py SECONDS BAD_EVERY`` corrupts the CRC of every
BAD_EVERY-th frame (as line noise would). Options:

- ``--rate-hz R``: R frames per second (default 1000);
- ``--count``: frame k carries k deg/s on every gyro in rate mode (decode with
  ``--kvh-rot rate --kvh-units deg --max-rate-dph 1e9``), so a sample tells which frame
  it came from: t_s x R = k on a right time base;
- ``--drop K:N`` (repeatable): the N frames from frame K vanish whole, without a byte
  gap (a device-side drop, an OS buffer overrun at frame boundaries);
- ``--wait``: send a zero byte every 20 ms (line noise, no frame) until a line arrives on
  stdin; frame 0 is due then;
- ``--report S``: every S s print ``at T s: N frames written, W s waited for room``
  (frames due and written so far, dropped ones included; how long the pty was full,
  i.e. the reader behind).

At the end it prints ``sent N frames``. Without
``--count`` every gyro sends delta angles in rad: z a constant 15 deg/h, x and y
0 deg/h, each plus its own white angle-rate noise of N = 0.05 deg/sqrt(h) (per-sample
rate std 60 N sqrt(fs) deg/h); the accelerometers send 1 g along z (a level unit) and
0 g along x and y."""
from __future__ import annotations

import argparse
import os
import select
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))   # tests/
from fogmon.sources.codecs.kvh import encode_frame  # noqa: E402
from helpers.fake_device import open_pty  # noqa: E402

RATE_HZ = 1000
BIAS_DPH = 15.0
N_DPSH = 0.05


def frames(n0: int, n: int, rng: np.random.Generator, bad_every: int = 0,
           rng_xy: np.random.Generator | None = None, rate_hz: float = RATE_HZ) -> bytes:
    """Frames n0 .. n0+n-1 (sequence numbers wrap at 128); every ``bad_every``-th with a bad CRC.
    The z noise comes from ``rng``, the x and y noise from ``rng_xy`` (none without it)."""
    sigma_dph = 60 * N_DPSH * np.sqrt(rate_hz)
    rate = BIAS_DPH + sigma_dph * rng.standard_normal(n)
    xy = sigma_dph * rng_xy.standard_normal((n, 2)) if rng_xy is not None else np.zeros((n, 2))
    to_rad = np.pi / 180.0 / 3600.0 / rate_hz
    out = []
    for i, r in enumerate(rate):
        f = encode_frame("a", (n0 + i) % 128, (xy[i, 0] * to_rad, xy[i, 1] * to_rad, r * to_rad), (0.0, 0.0, 1.0),
                         temp_c=31)
        if bad_every and (n0 + i) % bad_every == bad_every - 1:
            f = f[:-1] + bytes([f[-1] ^ 0xFF])
        out.append(f)
    return b"".join(out)


def counting_frames(n0: int, n: int) -> bytes:
    """Frames n0 .. n0+n-1, frame k carrying k deg/s on every gyro."""
    return b"".join(encode_frame("a", k % 128, (k, k, k), temp_c=25) for k in range(n0, n0 + n))


def run(seconds: float, bad_every: int = 0, rate_hz: float = RATE_HZ, count: bool = False,
        drops: tuple[tuple[int, int], ...] = (), wait: bool = False, report_s: float = 0.0) -> None:
    master, slave, path = open_pty()
    print(path, flush=True)
    while wait and not select.select([sys.stdin], [], [], 0.02)[0]:
        if select.select([], [master], [], 0)[1]:
            os.write(master, b"\x00")
    if wait:
        sys.stdin.readline()
    rng, rng_xy = np.random.default_rng(0), np.random.default_rng(1)
    gone = set().union(*(range(k, k + n) for k, n in drops))
    t0 = time.monotonic()
    n = 0
    waited = 0.0
    next_report = report_s
    while time.monotonic() - t0 < seconds:
        if report_s and time.monotonic() - t0 >= next_report:
            print(f"at {time.monotonic() - t0:.3f} s: {n} frames written, {waited:.3f} s waited for room", flush=True)
            next_report += report_s
        due = int((time.monotonic() - t0) * rate_hz)
        if due > n:
            data = counting_frames(n, due - n) if count else frames(n, due - n, rng, bad_every, rng_xy, rate_hz)
            if gone:
                data = b"".join(data[36 * i:36 * i + 36] for i in range(due - n) if n + i not in gone)
            view = memoryview(data)
            w0 = time.monotonic()
            while view and time.monotonic() - t0 < seconds + 5:  # the pty holds ~20 kB: wait, do not drop
                if select.select([], [master], [], 0.1)[1]:
                    view = view[os.write(master, view):]
            waited += time.monotonic() - w0
            n = due
        time.sleep(0.002 if rate_hz > 1000 else 0.01)
    print(f"sent {n} frames", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seconds", nargs="?", type=float, default=1e9)
    ap.add_argument("bad_every", nargs="?", type=int, default=0)
    ap.add_argument("--rate-hz", type=float, default=RATE_HZ)
    ap.add_argument("--count", action="store_true")
    ap.add_argument("--drop", action="append", default=[], metavar="K:N")
    ap.add_argument("--wait", action="store_true")
    ap.add_argument("--report", type=float, default=0.0, metavar="S")
    a = ap.parse_args(argv)
    drops = tuple((int(d.split(":")[0]), int(d.split(":")[1])) for d in a.drop)
    run(a.seconds, a.bad_every, a.rate_hz, a.count, drops, a.wait, a.report)


if __name__ == "__main__":
    main()
