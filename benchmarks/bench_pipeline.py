"""Pipeline benchmark (prints numbers; not a test).

1. Replay of one hour of 1 kHz gyro data (3.6 M samples) into an .rrd, through the whole
   pipeline (StreamingDadev, a noise fit per window, Rerun sink, console summary):
   seconds and x real time (target >= 300x), measured (a) from memory and (b) as the
   `fogmon replay` command on a replay-log CSV (CSV parsing included), beside the batch
   `dadev` of the same data (a reference measured in the same run).
   Three axes: the same hour as three axes of one stream (a StreamingDadev, fits and
   motion gate per axis) from memory, against the same hour as one axis (target: < 3x);
   without an .rrd unless --axes-rrd.
2. `fogmon monitor` on a fake 1 kHz KVH DSP-1760 (format A on a pty, tests/helpers/fake_kvh.py)
   writing an .rrd and the archive, with the live default window (65.536 s at 1 kHz, hop
   8.192 s; --monitor-window-s for another): CPU share of one core (all its threads) in
   steady state, from 10 s after the first window: three axes (target < 10 %), one axis,
   and one axis with --model and --thermal-cal (target < 5 %).
   Three axes live: the pipeline fed a paced 1 kHz stream of three axes in real time
   (blocks of 10 ms as a serial reader delivers them, read in its reader thread; an
   .rrd with --axes-rrd): CPU share of one core of the whole process in steady state
   (target < 10 %), beside the same for one axis.
3. `fogmon replay` of the bundled demo (replay_logs/lasergyro_z_100hz.csv, 184,718 samples)
   cold (an empty numba cache: every kernel compiled) and warm (the cache the cold run
   wrote), in CPU seconds split into import, compile, read, engine, fits, sinks
   (benchmarks/replay_split.py), the plain command's CPU time warm, and warm the CPU
   time until the first block has reached every sink (replay_split.py --first-sample),
   beside the same for a process that only imports numpy and Rerun and sends one block
   to an .rrd (benchmarks/rerun_floor.py: what any program writing a Rerun recording
   spends before its first sample); warm figures are medians of --demo-runs interleaved
   runs of each (the machine is shared) (targets: < 1 s before the first sample, < 3 s
   in all, fits < 10 %).

Usage: python benchmarks/bench_pipeline.py [--monitor-s 30] [--monitor-window-s 65.536] [--skip-monitor]
       [--skip-hour] [--skip-demo] [--demo-runs 5] [--skip-axes] [--axes-rrd]
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
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from fogmon.block import Block  # noqa: E402
from fogmon.cli.pipeline_options import add_pipeline_arguments, build_sinks, pipeline_config  # noqa: E402
from fogmon.davar.batch import dadev  # noqa: E402
from fogmon.formats.replay_log import write_replay_log  # noqa: E402
from fogmon.pipeline import default_window_s, run_pipeline  # noqa: E402
from fogmon.sources.base import OfflineSource  # noqa: E402

FS = 1000.0
LIVE_WINDOW_S = default_window_s(FS, None)
N = 3_600_000
BLOCK = 8192


AXES = ("x", "y", "z")


class MemorySource(OfflineSource):
    """One hour of 1 kHz white noise (N = 0.05 deg/sqrt(h)) plus 10 deg/h bias, in blocks
    (``axes``: ``rate`` has one column per axis)."""

    def __init__(self, rate, axes=()):
        self.name, self.sample_rate_hz, self.counters, self.n_samples = "memory (1 h at 1 kHz)", FS, {}, len(rate)
        self._rate, self.axes = rate, axes

    def blocks(self):
        for i in range(0, len(self._rate), BLOCK):
            r = self._rate[i:i + BLOCK]
            yield Block.make(np.arange(i, i + len(r)) / FS, r, aux={"temp_c": np.full(len(r), 25.0)}, axes=self.axes)

    def close(self):
        pass


def _args(argv):
    p = argparse.ArgumentParser()
    add_pipeline_arguments(p)
    return p.parse_args(argv)


def bench_replay(tmp: str) -> None:
    rng = np.random.default_rng(1)
    rate = 10.0 + 60 * 0.05 * np.sqrt(FS) * rng.standard_normal(N)
    t0 = time.perf_counter()
    ref = dadev(rate, FS, 2**19 / FS, 2**16 / FS)
    t_batch = time.perf_counter() - t0
    rrd = os.path.join(tmp, "mem.rrd")
    t0 = time.perf_counter()
    args = _args(["--rrd", rrd, "--no-progress", "--quiet"])
    s = run_pipeline(MemorySource(rate), pipeline_config(args), build_sinks(args))
    t_mem = time.perf_counter() - t0
    assert s.n_windows == len(ref), (s.n_windows, len(ref))
    print(f"replay 1 h of 1 kHz ({N:,} samples, window {s.window_s:g} s, hop {s.hop_s:g} s, "
          f"{s.n_windows} windows) into {os.path.getsize(rrd) / 1e6:.1f} MB .rrd:")
    print(f"  (a) pipeline from memory   : {t_mem:6.2f} s = x{3600 / t_mem:,.0f} real time "
          f"(target >= 300x: {'PASS' if 3600 / t_mem >= 300 else 'FAIL'})")
    print(f"      reference: batch dadev of the same data {t_batch:.2f} s; pipeline / batch = {t_mem / t_batch:.1f}")
    csv = os.path.join(tmp, "hour.csv")
    write_replay_log(csv, np.arange(N) / FS, rate, meta={"sample_rate_hz": FS})
    rrd2 = os.path.join(tmp, "cli.rrd")
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "fogmon", "replay", csv, "--rrd", rrd2, "--no-progress", "--quiet"],
                       capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    t_cli = time.perf_counter() - t0
    if p.returncode:
        print(p.stderr)
    print(f"  (b) `fogmon replay` of a {os.path.getsize(csv) / 1e6:.0f} MB CSV (parse + start-up included): "
          f"{t_cli:6.2f} s = x{3600 / t_cli:,.0f} real time "
          f"(target >= 300x: {'PASS' if 3600 / t_cli >= 300 else 'FAIL'})")


def _axes_args(tmp: str, name: str, rrd: bool):
    """The options of the axes measurements: quiet, and an .rrd when ``rrd``."""
    return _args(["--no-progress", "--quiet", *(["--rrd", os.path.join(tmp, name)] if rrd else [])])


def bench_replay_axes(tmp: str, rrd: bool) -> None:
    """The hour of bench_replay as one axis and as three axes, from memory (into an .rrd
    when ``rrd``)."""
    rng = np.random.default_rng(1)
    rate = 10.0 + 60 * 0.05 * np.sqrt(FS) * rng.standard_normal((N, 3))
    wall = {}
    for axes, r in (((), np.ascontiguousarray(rate[:, 0])), (AXES, rate)):
        args = _axes_args(tmp, f"axes{len(axes)}.rrd", rrd)
        t0 = time.perf_counter()
        s = run_pipeline(MemorySource(r, axes), pipeline_config(args), build_sinks(args))
        wall[len(axes)] = time.perf_counter() - t0
        assert s.n_windows > 0 and (not axes or all(x.overall_fit is not None for x in s.axes.values()))
    ratio = wall[3] / wall[0]
    print(f"replay 1 h of 1 kHz from memory ({'into an .rrd' if rrd else 'no .rrd'}), one axis vs three axes of "
          f"one stream:")
    print(f"  one axis {wall[0]:6.2f} s = x{3600 / wall[0]:,.0f} real time; three axes {wall[3]:6.2f} s = "
          f"x{3600 / wall[3]:,.0f} real time")
    print(f"  three axes / one axis = {ratio:.2f} (target < 3: {'PASS' if ratio < 3 else 'FAIL'})")


class PacedSource(OfflineSource):
    """A live-like source (``n_samples`` None): ``seconds`` s of 1 kHz samples of ``axes``
    (one axis when empty) in 10 ms blocks, each yielded when its last sample's time has
    come on the wall clock; records the process's CPU and wall time once ``skip_s`` s
    have passed and at the end."""

    def __init__(self, seconds: float, axes=(), skip_s: float = 5.0):
        self.name, self.sample_rate_hz, self.counters, self.n_samples = "paced 1 kHz", FS, {}, None
        self.axes, self.seconds, self.skip_s = axes, seconds, skip_s
        shape = (int(seconds * FS), len(axes)) if axes else int(seconds * FS)
        self._rate = 10.0 + 60 * 0.05 * np.sqrt(FS) * np.random.default_rng(2).standard_normal(shape)
        self.marks: list[tuple[float, float]] = []

    def blocks(self):
        step = int(0.01 * FS)
        w0 = time.monotonic()
        for i in range(0, len(self._rate), step):
            due = w0 + (i + step) / FS
            time.sleep(max(0.0, due - time.monotonic()))
            if not self.marks and time.monotonic() - w0 >= self.skip_s:
                self.marks.append((time.process_time(), time.monotonic()))
            r = self._rate[i:i + step]
            yield Block.make(np.arange(i, i + len(r)) / FS, r, aux={"temp_c": np.full(len(r), 25.0)}, axes=self.axes)
        self.marks.append((time.process_time(), time.monotonic()))

    def close(self):
        pass


def bench_live_axes(tmp: str, seconds: float, rrd: bool) -> None:
    """CPU share of one core of the pipeline on a paced 1 kHz stream, one and three axes
    (into an .rrd when ``rrd``)."""
    share = {}
    for axes in ((), AXES):
        src = PacedSource(seconds + 5.0, axes)
        args = _axes_args(tmp, f"live{len(axes)}.rrd", rrd)
        run_pipeline(src, pipeline_config(args), build_sinks(args))
        (c0, w0), (c1, w1) = src.marks[0], src.marks[-1]
        share[len(axes)] = 100 * (c1 - c0) / (w1 - w0)
    print(f"pipeline on a paced live 1 kHz stream (10 ms blocks, reader thread, {'.rrd' if rrd else 'no .rrd'}), "
          f"{seconds:.0f} s steady state:")
    print(f"  one axis: CPU {share[0]:.1f} % of one core; three axes: CPU {share[3]:.1f} % of one core "
          f"(target < 10 %: {'PASS' if share[3] < 10 else 'FAIL'}); three / one = {share[3] / share[0]:.2f}")


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (all its threads)."""
    with open(f"/proc/{pid}/stat") as fh:
        f = fh.read().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


MODEL_TOML = """[sensor]
sample_rate_hz = 1000.0
[noise]
Q_arcsec = 0.0
N_dpsh = 0.05
B_dph = 0.0
K_dphsh = 0.0
R_dphh = 0.0
"""
#: a thermal calibration as `fogmon thermal` writes it (the fake KVH's 31 deg C is constant)
CAL_TOML = MODEL_TOML.replace("N_dpsh = 0.05", "N_dpsh = 0.0") + """[[effect]]
kind = "thermal_drift"
k0_poly_dph = [0.5, 0.01]
k1_pos = 30.0
k1_neg = 18.0
k2_pos = 0.0
k2_neg = 0.0
"""


def _monitor_share(tmp: str, window_s: float, seconds: float, extra: list[str]) -> tuple[float, str, int]:
    """(CPU % of one core of a monitor of the fake KVH, all its threads, from 10 s after
    its first window for ``seconds``; its samples_missing; its exit code)."""
    lead_s = window_s + 10.0
    fake_kvh = ROOT / "tests" / "helpers" / "fake_kvh.py"
    dev = subprocess.Popen([sys.executable, str(fake_kvh), str(lead_s + seconds + 30)],
                           stdout=subprocess.PIPE, text=True)
    port = dev.stdout.readline().strip()
    mon = subprocess.Popen([sys.executable, "-m", "fogmon", "monitor", "--serial", port, "--protocol", "kvh-a",
                            "--duration-s", str(lead_s + seconds + 5), "--window-s", str(window_s),
                            "--archive", tmp, "--rrd", os.path.join(tmp, "live.rrd"),
                            "--no-progress", *extra],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        time.sleep(lead_s)                   # start-up, band simulation and the first window excluded
        c0, w0 = _cpu_s(mon.pid), time.monotonic()
        time.sleep(seconds)
        c1, w1 = _cpu_s(mon.pid), time.monotonic()
        out, err = mon.communicate(timeout=120)
    finally:
        dev.kill()
        dev.wait()
    if mon.returncode:
        print(err.strip().splitlines()[-1] if err.strip() else f"monitor exit {mon.returncode}")
    gaps = next((ln.split()[-1] for ln in out.splitlines() if ln.strip().startswith("samples_missing")), "?")
    shutil.rmtree(os.path.join(tmp, "arch"), ignore_errors=True)
    return 100 * (c1 - c0) / (w1 - w0), gaps, mon.returncode


def bench_monitor(tmp: str, seconds: float, window_s: float) -> None:
    model, cal = os.path.join(tmp, "model.toml"), os.path.join(tmp, "cal.toml")
    Path(model).write_text(MODEL_TOML)
    Path(cal).write_text(CAL_TOML)
    cases = (("three axes (gyros x, y, z and the accelerometers)", [], 10.0),
             ("one axis (--axis z)", ["--axis", "z"], None),
             ("one axis with --model and --thermal-cal", ["--axis", "z", "--model", model, "--thermal-cal", cal], 5.0))
    print(f"monitor, fake KVH DSP-1760 format A at 1 kHz on a pty, --rrd + archive, window {window_s:g} s "
          f"(hop {window_s / 8:g} s), {seconds:.0f} s steady state:")
    for what, extra, target in cases:
        share, gaps, code = _monitor_share(tmp, window_s, seconds, extra)
        verdict = f" (target < {target:g} %: {'PASS' if share < target else 'FAIL'})" if target else ""
        print(f"  {what}: CPU {share:.1f} % of one core{verdict}; samples_missing {gaps}; exit {code}")


DEMO = ROOT / "replay_logs" / "lasergyro_z_100hz.csv"


def _child_cpu_s(cmd, env) -> tuple[float, subprocess.CompletedProcess]:
    """CPU seconds (user + system) of a child process run to completion, and its result."""
    before = os.times()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    after = os.times()
    return (after.children_user - before.children_user) + (after.children_system - before.children_system), p


def _split(cmd, env) -> dict[str, float]:
    """The ``key=value`` figures replay_split.py prints (empty, with its error, on failure)."""
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    vals = dict(line.split("=", 1) for line in p.stdout.splitlines() if "=" in line)
    if p.returncode or vals.get("rc") != "0":
        print(p.stderr[-2000:])
        return {}
    return {k: float(v) for k, v in vals.items()}


def bench_demo(tmp: str, runs: int) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": os.path.join(tmp, "numba_cache")}
    rrd = os.path.join(tmp, "demo.rrd")
    split_cmd = [sys.executable, str(ROOT / "benchmarks" / "replay_split.py"), str(DEMO), rrd]
    floor_cmd = [sys.executable, str(ROOT / "benchmarks" / "rerun_floor.py"), rrd]
    plain_cmd = [sys.executable, "-m", "fogmon", "replay", str(DEMO), "--rrd", rrd, "--no-progress", "--quiet"]
    print(f"`fogmon replay` of {DEMO.name} (CPU s; numba cache {env['NUMBA_CACHE_DIR']}; warm: medians of {runs} "
          f"runs of each, interleaved):")
    keys = ("import", "compile", "read", "engine", "fits", "sinks", "other", "first_read", "total")
    print("  " + " ".join(f"{k:>12s}" for k in ("run",) + keys))
    cold = _split(split_cmd, env)
    if not cold:
        return
    warm: dict[str, list[float]] = {}
    for _ in range(runs):
        for k, v in _split(split_cmd, env).items():
            warm.setdefault(k, []).append(v)
        warm.setdefault("plain", []).append(_child_cpu_s(plain_cmd, env)[0])
        warm.setdefault("first_sample", []).append(_split([*split_cmd, "--first-sample"], env)["first_sample"])
        warm.setdefault("floor", []).append(_split(floor_cmd, env)["first_sample"])
    w = {k: float(np.median(v)) for k, v in warm.items()}
    for run, row in (("cold", cold), ("warm", w)):
        print("  " + " ".join(f"{x:>12s}" for x in [run] + [f"{row[k]:.2f}" for k in keys]))
    cpu, first = w["plain"], w["first_sample"]
    spread = {k: f"{min(warm[k]):.2f}-{max(warm[k]):.2f}" for k in ("plain", "first_sample", "floor")}
    print(f"  plain `fogmon replay`, warm: {cpu:.2f} CPU s ({spread['plain']})")
    print(f"  {'PASS' if first < 1.0 else 'FAIL'}  warm: before the first sample < 1 s: {first:.2f} s "
          f"({spread['first_sample']}; the program's own order, interpreter start-up included, until the first "
          f"block is in every sink); numpy + Rerun alone, one block into an .rrd: {w['floor']:.2f} s "
          f"({spread['floor']}), {first / w['floor']:.2f}x")
    print(f"  {'PASS' if cpu < 3.0 else 'FAIL'}  warm: whole demo < 3 s: {cpu:.2f} s")
    print(f"  {'PASS' if w['fits'] < 0.1 * w['total'] else 'FAIL'}  warm: fits < 10 % of the replay: "
          f"{100 * w['fits'] / w['total']:.1f} % ({w['fits']:.2f} s, of which {w['fit_cov']:.2f} s the cross-tau "
          f"covariance matrices, once per tau grid)")
    print(f"  first-run cost (cold - warm): {cold['total'] - w['total']:.1f} CPU s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--monitor-s", type=float, default=30.0, help="steady-state seconds to measure the monitor")
    ap.add_argument("--skip-monitor", action="store_true")
    ap.add_argument("--skip-hour", action="store_true", help="skip the one-hour 1 kHz replay")
    ap.add_argument("--skip-demo", action="store_true", help="skip the cold/warm replay of the bundled demo")
    ap.add_argument("--demo-runs", type=int, default=5, help="warm runs of the demo (medians printed)")
    ap.add_argument("--skip-axes", action="store_true", help="skip the three-axis replay and live measurements")
    ap.add_argument("--axes-rrd", action="store_true", help="the three-axis measurements also write an .rrd")
    ap.add_argument("--monitor-window-s", type=float, default=LIVE_WINDOW_S,
                    help="DADEV window of the measured monitors, s (default: the live default at 1 kHz)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if not a.skip_demo:
            bench_demo(tmp, a.demo_runs)
        if not a.skip_hour:
            bench_replay(tmp)
        if not a.skip_axes and not a.skip_hour:
            bench_replay_axes(tmp, a.axes_rrd)
        if not a.skip_monitor:
            bench_monitor(tmp, a.monitor_s, a.monitor_window_s)
        if not a.skip_axes and not a.skip_monitor:
            bench_live_axes(tmp, a.monitor_s, a.axes_rrd)


if __name__ == "__main__":
    main()
