"""The speed a user feels, in one run (issue 33): the first run after a fresh numba cache
against a warm run for the README demo and the configurations after it, and the hop-1
push against the engine (benchmarks/bench_first_run.py); explain's time for 1e6 and 1e7
samples and a three-axis 2 h record at 100 Hz beside allantools' oadev of the same data,
and one long recording's explain split across 2 Dask workers against one task
(benchmarks/bench_explain.py --batch).

Each part runs as its own child process (each measures its own references in the same
run); their lines are printed as they come, then every goal line again as a summary.

Run:  python benchmarks/bench_speed.py [--runs 3] [--no-batch]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def part(args: list[str]) -> tuple[int, list[str]]:
    """Run one benchmark script, echo its output; (exit code, its lines)."""
    proc = subprocess.Popen([sys.executable, *args], stdout=subprocess.PIPE, text=True, bufsize=1)
    lines = []
    assert proc.stdout is not None
    for line in proc.stdout:
        print(line, end="", flush=True)
        lines.append(line.rstrip("\n"))
    return proc.wait(), lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="warm runs per configuration and hop-1 repeats")
    ap.add_argument("--no-batch", action="store_true", help="leave out the Dask split of one long recording")
    a = ap.parse_args()
    rc_first, first = part([str(HERE / "bench_first_run.py"), "--runs", str(a.runs)])
    rc_explain, explained = part([str(HERE / "bench_explain.py"), *([] if a.no_batch else ["--batch"])])
    goals = [line for line in first + explained if "PASS" in line or "FAIL" in line or "speed-up" in line]
    print("\nsummary:")
    for line in goals:
        print(" ", line.strip())
    failed = rc_first != 0 or rc_explain != 0 or any("FAIL" in line for line in goals)
    print("all goals PASS" if not failed else "some goal FAILED")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
