"""`fogmon batch` benchmark (prints numbers; not a test): R recordings (default 16) of H h
(default 1) at 1 kHz, written once as Parquet logs into a temporary folder, analysed by
`fogmon batch` on a local Dask cluster of 1 worker and of 2 workers (one thread each),
beside the single-process `fogmon replay` of one of the recordings measured in the same
run (the reference):

- speed-up of 2 workers over 1 (ideally ~2 on 2 free cores);
- throughput per core of batch (samples / wall s / workers) over that of the
  single-process replay (1.0 = no Dask overhead; includes batch's checking pass);
- peak RSS of each worker (VmHWM of the worker process, MB) against the replay's.

Usage: python benchmarks/bench_batch.py [--recordings 16] [--hours 1] [--dir /tmp]
"""
from __future__ import annotations

import argparse
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from fogmon.formats.parquet_log import ParquetLogWriter  # noqa: E402

FS = 1000.0
CHUNK = 1 << 20

REPLAY = """
import sys, time
from fogmon.cli import main
t0 = time.perf_counter()
rc = main(["replay", sys.argv[1], "--no-progress", "--quiet"])
dt = time.perf_counter() - t0
hwm = next(l for l in open("/proc/self/status") if l.startswith("VmHWM")).split()[1]
print(rc, dt, int(hwm) / 1024)
"""


def write_recording(path: Path, hours: float, seed: int) -> int:
    """``hours`` of a 1 kHz gyro: 15 deg/h bias, white noise (N = 0.05 deg/sqrt(h)), a slow
    random walk, temp_c."""
    n = int(hours * 3600 * FS)
    rng = np.random.default_rng(seed)
    w = ParquetLogWriter(str(path), ["temp_c"], {"sample_rate_hz": FS, "sensor": f"bench gyro {seed}"})
    walk = 0.0
    for i in range(0, n, CHUNK):
        k = np.arange(i, min(i + CHUNK, n))
        rw = walk + np.cumsum(rng.standard_normal(len(k))) * 1e-3
        walk = float(rw[-1])
        w.write(k / FS, 15.0 + 60 * 0.05 * np.sqrt(FS) * rng.standard_normal(len(k)) + rw,
                {"temp_c": 25.0 + 0.5 * np.sin(k / FS / 900.0)})
    w.close()
    return n


def _hwm() -> float:
    return int(next(ln for ln in open("/proc/self/status") if ln.startswith("VmHWM")).split()[1]) / 1024


def run_batch(folder: str, out: str, workers: int) -> tuple[float, list[float]]:
    """(wall s, peak RSS MB per worker) of `fogmon batch folder --out out` on a fresh local
    cluster of ``workers`` processes."""
    from distributed import Client, LocalCluster

    from fogmon.cli import main

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        t0 = time.perf_counter()
        rc = main(["batch", folder, "--out", out, "--scheduler", cluster.scheduler_address, "--no-progress"])
        dt = time.perf_counter() - t0
        assert rc == 0
        rss = sorted(client.run(_hwm).values())
    return dt, rss


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--recordings", type=int, default=16)
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--dir", default=None)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory(dir=a.dir) as d:
        rec = Path(d) / "fleet"
        rec.mkdir()
        n = sum(write_recording(rec / f"gyro{i:02d}.parquet", a.hours, i) for i in range(a.recordings))
        print(f"{a.recordings} recordings x {a.hours:g} h at {FS:g} Hz = {n:,} samples (Parquet), "
              f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start")
        out = subprocess.run([sys.executable, "-c", REPLAY, str(rec / "gyro00.parquet")], stdout=subprocess.PIPE,
                             text=True, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)}).stdout.split()
        t_rep, rss_rep = float(out[1]), float(out[2])
        per_rec = n / a.recordings
        print(f"reference: fogmon replay of one recording (single process): {t_rep:.1f} s = "
              f"{per_rec / t_rep / 1e6:.3f} M samples/s, peak RSS {rss_rep:.0f} MB")
        walls = {}
        for workers in (1, 2):
            t, rss = run_batch(str(rec), str(Path(d) / f"out{workers}"), workers)
            walls[workers] = t
            print(f"batch on {workers} worker(s): {t:.1f} s = {n / t / 1e6:.3f} M samples/s; per core "
                  f"{n / t / workers / (per_rec / t_rep):.2f}x the single-process replay; peak RSS per worker "
                  + ", ".join(f"{r:.0f}" for r in rss) + " MB")
        print(f"speed-up 2 workers / 1 worker: {walls[1] / walls[2]:.2f}x")


if __name__ == "__main__":
    main()
