"""A fake KVH DSP-1760 (binary format A, 1000 Hz) on a pseudo-terminal, for the monitor
tests and benchmarks/bench_pipeline.py: ``python tests/helpers/fake_kvh.py [SECONDS]``
prints the device path (the pty's slave side) on stdout and sends frames at the device's
pace (10 frames every 10 ms) until SECONDS have passed or it is killed;
``python tests/helpers/fake_kvh.py SECONDS BAD_EVERY`` corrupts the CRC of every
BAD_EVERY-th frame (as line noise would).

Every gyro sends delta angles in rad: z a constant 15 deg/h, x and y 0 deg/h, each plus
its own white angle-rate noise of N = 0.05 deg/sqrt(h) (per-sample rate std
60 N sqrt(fs) deg/h); the accelerometers send 1 g along z (a level unit) and 0 g along
x and y."""
from __future__ import annotations

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
DPH_TO_RAD_PER_SAMPLE = np.pi / 180.0 / 3600.0 / RATE_HZ


def frames(n0: int, n: int, rng: np.random.Generator, bad_every: int = 0,
           rng_xy: np.random.Generator | None = None) -> bytes:
    """Frames n0 .. n0+n-1 (sequence numbers wrap at 128); every ``bad_every``-th with a bad CRC.
    The z noise comes from ``rng``, the x and y noise from ``rng_xy`` (none without it)."""
    sigma_dph = 60 * N_DPSH * np.sqrt(RATE_HZ)
    rate = BIAS_DPH + sigma_dph * rng.standard_normal(n)
    xy = sigma_dph * rng_xy.standard_normal((n, 2)) if rng_xy is not None else np.zeros((n, 2))
    out = []
    for i, r in enumerate(rate):
        gyro = (xy[i, 0] * DPH_TO_RAD_PER_SAMPLE, xy[i, 1] * DPH_TO_RAD_PER_SAMPLE, r * DPH_TO_RAD_PER_SAMPLE)
        f = encode_frame("a", (n0 + i) % 128, gyro, (0.0, 0.0, 1.0), temp_c=31)
        if bad_every and (n0 + i) % bad_every == bad_every - 1:
            f = f[:-1] + bytes([f[-1] ^ 0xFF])
        out.append(f)
    return b"".join(out)


def run(seconds: float, bad_every: int = 0) -> None:
    master, slave, path = open_pty()
    print(path, flush=True)
    rng, rng_xy = np.random.default_rng(0), np.random.default_rng(1)
    t0 = time.monotonic()
    n = 0
    while time.monotonic() - t0 < seconds:
        due = int((time.monotonic() - t0) * RATE_HZ)
        if due > n:
            view = memoryview(frames(n, due - n, rng, bad_every, rng_xy))
            while view and time.monotonic() - t0 < seconds:  # the pty holds ~20 kB: wait, do not drop
                if select.select([], [master], [], 0.1)[1]:
                    view = view[os.write(master, view):]
            n = due
        time.sleep(0.01)


if __name__ == "__main__":
    run(float(sys.argv[1]) if len(sys.argv) > 1 else 1e9, int(sys.argv[2]) if len(sys.argv) > 2 else 0)
