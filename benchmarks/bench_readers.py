"""Reading speed of the other-format readers (fogmon.sources.files, table: fogmon.sources.open), as ratios to the
replay-log CSV reader on the same samples, measured in the same run: open the file and
iterate every block. Files are written with the test suite's writers (tests/helpers/recordings.py).

    python benchmarks/bench_readers.py [N_SAMPLES]
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))
from helpers import recordings as w  # noqa: E402  (the writers)

from fogmon.formats.replay_log import write_replay_log  # noqa: E402
from fogmon.sources.open import open_replay_source  # noqa: E402
from fogmon.sources.options import SourceOptions  # noqa: E402


def timed(path, **opts) -> float:
    """Best of 3: open ``path`` and read every block, s."""
    args = SourceOptions(**opts)
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        sum(len(b) for b in open_replay_source(str(path), args).blocks())
        best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 100_000
    sample_rate_hz = 100.0
    rng = np.random.default_rng(1)
    t = np.arange(n) / sample_rate_hz
    rate = 60 * 0.1 * np.sqrt(sample_rate_hz) * rng.standard_normal(n)
    keep = np.ones(n, bool)
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        write_replay_log(d / "ref.csv", t, rate, meta={"sample_rate_hz": sample_rate_hz})
        t_csv = timed(d / "ref.csv")
        print(f"replay-log CSV: {n / t_csv:,.0f} samples/s (reference)")
        cases = []
        w.write_imu_bag(d / "run.bag", t, rate, keep, "ros1")
        cases.append(("ROS 1 bag", d / "run.bag", {}))
        w.write_imu_bag(d / "bag2", t, rate, keep, "mcap")
        cases.append(("ROS 2 bag (MCAP storage)", d / "bag2", {}))
        w.write_ulog(d / "f.ulg", t, rate, keep)
        cases.append(("PX4 ULog", d / "f.ulg", {}))
        w.write_mdf(d / "b.mf4", t, rate, keep)
        cases.append(("MDF4 channel", d / "b.mf4", {"channel": "GyroZ"}))
        w.write_las(d / "t.las", t, rate, keep)
        cases.append(("LAS", d / "t.las", {}))
        for name, path, opts in cases:
            s = timed(path, **opts)
            print(f"{name}: {n / s:,.0f} samples/s = {t_csv / s:.2f}x the CSV reader "
                  f"({n / sample_rate_hz / s:,.0f}x real time at {sample_rate_hz:g} Hz)")


if __name__ == "__main__":
    main()
