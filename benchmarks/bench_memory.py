"""Memory benchmark (prints numbers; not a test): peak RSS of `fogmon replay`.

1. A generated replay log of H hours at 2 kHz (24 h = 172.8 M samples, written to a
   temporary file in chunks): peak RSS, file size and wall time, beside the same command
   on a 10-minute log of the same kind (the reference, measured in the same run): memory
   must not grow with the file (target < 500 MB for 24 h).
2. The simulated source (`fogmon replay MODEL.toml`, endless, as fast as it can) for M
   minutes of simulated time at 2 kHz, beside 1 minute (reference): memory must not grow
   with the run (it grew without limit before the reader queue was bounded).

Peak RSS is the child's own high-water mark from the kernel (os.wait4 ru_maxrss), so no
sampling can miss a peak. Usage:
  python benchmarks/bench_memory.py [--hours 24] [--sim-minutes 120] [--dir /tmp] [--rrd]
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from fogmon.formats.replay_log import write_replay_header  # noqa: E402

FS = 2000.0
ROWS_PER_WRITE = 2_000_000


def write_log(path: Path, hours: float) -> int:
    """A replay log of ``hours`` of 2 kHz white noise (deg/h) plus a bias, written in
    chunks with pyarrow's CSV writer; returns the number of rows."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    n = int(round(hours * 3600 * FS))
    rng = np.random.default_rng(1)
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        write_replay_header(fh, [], {"sample_rate_hz": f"{FS:g}", "sensor": "bench_memory white noise"})
    with open(path, "ab") as fh:
        for i in range(0, n, ROWS_PER_WRITE):
            k = np.arange(i, min(i + ROWS_PER_WRITE, n))
            tbl = pa.table({"time_s": k / FS, "rate_dph": np.round(0.5 + 3.0 * rng.standard_normal(len(k)), 6)})
            pacsv.write_csv(tbl, fh, pacsv.WriteOptions(include_header=False))
    return n


def peak_rss(argv: list[str]) -> tuple[float, float, int]:
    """(peak RSS in MB, wall s, exit code) of running ``argv``."""
    t0 = time.monotonic()
    p = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.monotonic() - t0
    err = p.stderr.read().decode(errors="replace")
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode:
        print(f"  ! exit {p.returncode}: {err.strip()[-300:]}")
    return usage.ru_maxrss / 1024.0, wall, p.returncode  # ru_maxrss is in KiB on Linux


def fogmon(*args: str) -> list[str]:
    return [sys.executable, "-m", "fogmon", *args]


def bench_log(tmp: Path, hours: float, rrd: bool) -> None:
    print(f"1. fogmon replay of a {FS:g} Hz replay log (console summary{' and --rrd' if rrd else ' only, no --rrd'})")
    runs = []
    for h in (10 / 60, hours):
        path = tmp / f"log_{h:g}h.csv"
        t0 = time.monotonic()
        n = write_log(path, h)
        gen_s = time.monotonic() - t0
        size_mb = path.stat().st_size / 1e6
        out = ["--rrd", str(tmp / "out.rrd")] if rrd else []
        rss, wall, rc = peak_rss(fogmon("replay", str(path), "--no-progress", *out))
        runs.append(rss)
        rrd_mb = f", .rrd {(tmp / 'out.rrd').stat().st_size / 1e6:,.0f} MB" if rrd and rc == 0 else ""
        print(f"  {h * 60 if h < 1 else h:g} {'min' if h < 1 else 'h'}: {n:,} samples, file {size_mb:,.0f} MB "
              f"(written in {gen_s:.0f} s){rrd_mb}: peak RSS {rss:,.0f} MB, {wall:.0f} s "
              f"(x{h * 3600 / wall:,.0f} real time){'' if rc == 0 else '  FAILED'}")
        path.unlink()
    print(f"  peak RSS {hours:g} h / 10 min = {runs[1] / runs[0]:.2f}; target < 500 MB for 24 h: "
          f"{'met' if runs[1] < 500 else 'NOT met'} ({runs[1]:,.0f} MB{'' if hours >= 24 else f' for {hours:g} h'})")


def bench_sim(tmp: Path, minutes: float) -> None:
    print(f"2. fogmon replay MODEL.toml (simulated source, as fast as it can, {FS:g} Hz)")
    model = (ROOT / "fogmon/data/example_model.toml").read_text()
    path = tmp / "model_2khz.toml"
    path.write_text(model.replace("sample_rate_hz = 100.0", f"sample_rate_hz = {FS:g}"))
    runs = []
    for m in (1.0, minutes):
        rss, wall, rc = peak_rss(fogmon("replay", str(path), "--duration-s", f"{m * 60:g}", "--no-progress"))
        runs.append(rss)
        print(f"  {m:g} min simulated ({m * 60 * FS:,.0f} samples): peak RSS {rss:,.0f} MB, {wall:.0f} s "
              f"(x{m * 60 / wall:,.1f} real time){'' if rc == 0 else '  FAILED'}")
    print(f"  peak RSS {minutes:g} min / 1 min = {runs[1] / runs[0]:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0, help="length of the big replay log in h (default 24)")
    ap.add_argument("--sim-minutes", type=float, default=120.0, help="simulated minutes (default 120)")
    ap.add_argument("--dir", default=None, help="folder for the temporary files (default: the system's)")
    ap.add_argument("--rrd", action="store_true", help="replay the logs into an .rrd too (Rerun sink)")
    ap.add_argument("--skip-log", action="store_true")
    ap.add_argument("--skip-sim", action="store_true")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="fogmon-bench-memory-", dir=a.dir))
    need_gb = a.hours * 3600 * FS * 24 / 1e9  # ~24 bytes per row
    free_gb = shutil.disk_usage(tmp).free / 1e9
    print(f"temporary folder {tmp}: {free_gb:,.0f} GB free, the log needs ~{need_gb:,.1f} GB")
    if not a.skip_log and need_gb > 0.8 * free_gb:
        sys.exit(f"not enough disk space for a {a.hours:g} h log: use --hours")
    try:
        if not a.skip_log:
            bench_log(tmp, a.hours, a.rrd)
        if not a.skip_sim:
            bench_sim(tmp, a.sim_minutes)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
