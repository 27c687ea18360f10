"""Cost of the live model check (fogmon.modelcheck) at 1 kHz, window 2^16, hop 2^14.

Prints, each next to a reference measured in the same run so the ratios travel across
machines:
- the band build (wall and CPU time, default replicates, white + flicker + random-walk model, no cache)
  against one simulation + one ``oadev`` of a 2^16-sample window (the bootstrap's unit
  of work), and against the cached load;
- ``ModelWatch.frame`` per window (three aux channels) against ``StreamingDadev.push``
  of one hop of samples, and as a fraction of a core at 1 kHz (frame time / hop time).

Run:  python benchmarks/bench_modelcheck.py [--frames 200]
"""
from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from fogmon.davar.batch import oadev
from fogmon.davar.streaming import StreamingDadev
from fogmon.modelcheck import ModelBand, ModelWatch
from fogmon.modelcheck.band import DEFAULT_REPLICATES
from fogmon.sim.model import Noise, SensorModel
from fogmon.sim.simulate import simulate

FS, W, HOP = 1000.0, 1 << 16, 1 << 14


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200, help="ModelWatch.frame calls timed")
    a = ap.parse_args()
    model = SensorModel(FS, 0.0, Noise(N_dpsh=0.01, B_dph=0.05, K_dphsh=0.02))
    sd = StreamingDadev(FS, W / FS, hop_s=HOP / FS, alpha=0)
    ModelBand.for_model(model, FS, W, sd.m, replicates=8, cache_dir=tempfile.mkdtemp())  # warm-up
    t0 = time.perf_counter()
    rec = simulate(model, duration_s=W / FS, seed=1)
    oadev(rec.rate_dph, FS, taus=sd.m / FS, alpha=0)
    unit = time.perf_counter() - t0
    print(f"reference: one simulation + one oadev of a {W}-sample window: {unit * 1e3:.1f} ms")
    with tempfile.TemporaryDirectory() as d:
        t0, c0 = time.perf_counter(), time.process_time()
        band = ModelBand.for_model(model, FS, W, sd.m, cache_dir=d)
        build, cpu = time.perf_counter() - t0, time.process_time() - c0
        t0 = time.perf_counter()
        ModelBand.for_model(model, FS, W, sd.m, cache_dir=d)
        cached = time.perf_counter() - t0
    print(f"band build, {DEFAULT_REPLICATES} replicates: {build:.2f} s ({cpu:.2f} s CPU) = "
          f"{build / unit:.0f} x the reference "
          f"({build / DEFAULT_REPLICATES / unit:.2f} x per replicate); from the cache: {cached * 1e3:.1f} ms")

    long = simulate(model, duration_s=(W + HOP * 8) / FS, seed=2).rate_dph
    r = sd.push(long[:W])
    t0 = time.perf_counter()
    pushes = 0
    for k in range(W, len(long), HOP):
        sd.push(long[k:k + HOP])
        pushes += 1
    push = (time.perf_counter() - t0) / pushes
    watch = ModelWatch(band, ("vib_g", "temp_c", "rot_dps"))
    rng = np.random.default_rng(0)
    aux = {"vib_g": rng.normal(size=W) * 0.01, "temp_c": 25 + rng.normal(size=W) * 0.01, "rot_dps": np.zeros(W)}
    adev = r.adev_dph[-1]
    t0 = time.perf_counter()
    for i in range(a.frames):
        watch.frame(W / FS + i * HOP / FS, adev, aux)
    frame = (time.perf_counter() - t0) / a.frames
    print(f"ModelWatch.frame: {frame * 1e3:.2f} ms per window = {frame / push:.3f} x StreamingDadev.push of one "
          f"hop ({push * 1e3:.1f} ms); {100 * frame / (HOP / FS):.4f} % of a core at {FS:g} Hz")


if __name__ == "__main__":
    main()
