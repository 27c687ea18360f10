"""Archive format benchmark (prints numbers; not a test): the Parquet replay log against
the CSV one, for H hours (default 1) of a 1 kHz gyro (rate_dph white noise + bias,
temp_c, as `fogmon monitor` archives it: 12 significant digits in the CSV).

Prints, measured in the same run: bytes per sample and per day per axis of each format
(the day extrapolated from the H hours), the size ratio; the time to read the whole
recording as a replay source (the checking pass + every block, as `fogmon replay`
does) and as one in-memory Recording (`fogmon explain`), CSV over Parquet; and each
reader's peak RSS in a child process (its VmHWM), against the same child reading
nothing (the interpreter + imports). Usage:
  python benchmarks/bench_archive.py [--hours 1] [--dir /tmp]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from fogmon.formats.replay_log import append_replay_rows, write_replay_header  # noqa: E402

FS = 1000.0
CHUNK = 1_000_000

READ = """
import sys, time
from fogmon.sources.open import open_replay_source
from fogmon.formats.replay_log import read_replay_log
what, path = sys.argv[1], sys.argv[2]
t0 = time.perf_counter()
if what == "source":
    src = open_replay_source(path, None)
    n = sum(len(b) for b in src.blocks())
elif what == "recording":
    n = len(read_replay_log(path))
else:
    n = 0
dt = time.perf_counter() - t0
hwm = next(l for l in open("/proc/self/status") if l.startswith("VmHWM")).split()[1]   # kB, this process only
print(n, dt, int(hwm) / 1024)
"""


def write_csv(path: Path, hours: float) -> int:
    n = int(hours * 3600 * FS)
    rng = np.random.default_rng(0)
    with open(path, "w", encoding="utf-8") as fh:
        write_replay_header(fh, ["temp_c"], {"sample_rate_hz": FS, "sensor": "bench gyro"})
        for i in range(0, n, CHUNK):
            k = np.arange(i, min(i + CHUNK, n))
            append_replay_rows(fh, k / FS, 15.0 + 95.0 * rng.standard_normal(len(k)),
                               {"temp_c": 25.0 + 0.5 * np.sin(k / FS / 600.0)})
    return n


def child(what: str, path: str) -> tuple[float, float]:
    """(seconds, peak RSS MB) of a child reading ``path`` (VmHWM of its own address space:
    ru_maxrss would carry the parent's high-water mark over the fork)."""
    out = subprocess.run([sys.executable, "-c", READ, what, path], stdout=subprocess.PIPE, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}).stdout.split()
    return float(out[1]), float(out[2])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--dir", default=None)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory(dir=a.dir) as d:
        csv, pq = Path(d) / "run.csv", Path(d) / "run.parquet"
        n = write_csv(csv, a.hours)
        from fogmon.cli import main as fogmon
        assert fogmon(["convert", str(csv), str(pq)]) == 0
        per_day = 86400 * FS / n
        s_csv, s_pq = csv.stat().st_size, pq.stat().st_size
        print(f"{n:,} samples ({a.hours:g} h at {FS:g} Hz, columns time_s, rate_dph, temp_c)")
        print(f"size  CSV     {s_csv / n:6.2f} B/sample  {s_csv * per_day / 1e9:6.2f} GB/day/axis")
        print(f"size  Parquet {s_pq / n:6.2f} B/sample  {s_pq * per_day / 1e9:6.2f} GB/day/axis  "
              f"(CSV / Parquet = {s_csv / s_pq:.2f}x)")
        _, rss0 = child("nothing", str(csv))
        for what, label in (("source", "replay source (check pass + blocks)"), ("recording", "whole Recording")):
            t_c, m_c = child(what, str(csv))
            t_p, m_p = child(what, str(pq))
            print(f"read  {label:36s} CSV {t_c:6.2f} s ({n / t_c / 1e6:5.2f} M samples/s), Parquet {t_p:6.2f} s "
                  f"({n / t_p / 1e6:5.2f} M samples/s): Parquet {t_c / t_p:.2f}x faster")
            print(f"      peak RSS above the bare interpreter ({rss0:.0f} MB): CSV {m_c - rss0:6.0f} MB, "
                  f"Parquet {m_p - rss0:6.0f} MB")


if __name__ == "__main__":
    main()
