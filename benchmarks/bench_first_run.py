"""First run after a fresh numba cache against a warm run, in CPU seconds (issue 33).

Every run is the ``fogmon`` program in a child process (CPU time of the children,
``resource.getrusage``: user + system), with its own numba cache (``NUMBA_CACHE_DIR``
in a temporary folder, empty at the start: what a new installation has):

1. the README demo, ``fogmon replay replay_logs/lasergyro_z_100hz.csv --rrd out.rrd``:
   its first run with the empty cache against its warm run (goal <= 6x);
2. after that first run, in the same cache, other configurations, each its first run
   against its warm run (goal <= 2x each: nothing compiles again): a CAN replay (a
   .blf log of the bundled example DBC written by python-can, 100 Hz, 10 min with a
   lost stretch), ``--duration-s 5`` (a 5 s run: hop below 64 samples, the running-sum
   engine), a three-axis replay log (100 Hz, 1000 s), hop 1 (the demo's first 30 s,
   ``--window-s 20 --hop-s 0.01``: a window per sample) and ``fogmon explain`` of the
   bundled 1 Hz ``sim_mwd_run_1hz.csv``;
3. then, in this process and from the same cache, issue 33's hop-1 ratio: the push at
   hop 1 (alpha=0) against the engine alone at hop 1024, samples per CPU s, best of
   ``--runs`` interleaved repeats (benchmarks/bench_davar.py's rows "push alpha=0,
   hop 1" and "engine alone (advance), hop 1024"; goal >= 0.25x), and the engine alone
   at hop 1 (what the push at hop 1 can at most reach). The push forms no adev: a
   ``DadevResult`` forms it from the windows' sums when first read; the same push with
   every window's adev read is printed beside it (bench_davar.py's row "push alpha=0,
   hop 1, every adev read": what a reader of every window pays).

Warm figures are medians of ``--runs`` runs of each, interleaved (the machine is shared);
the first runs are single runs (a first run happens once). Where the install built the
kernels ahead of time (``fogmon._kernels_aot``, fogmon/jit.py) no run compiles; ``--no-aot``
adds the same table with that module switched off (``jit.use_ahead_of_time = False``: a
machine where it could not be built), whose first run compiles: its compile is the CPU
time the warm-up line on stderr reports (``fogmon.jit``: the first run compiles every
kernel of every command once). ``--lazy`` adds the same table with that warm-up
switched off (each kernel compiled when a run first needs it, numba's own way): the
alternative it was measured against. ``--kernels`` adds where the compile goes: each
declared kernel's compile CPU s (its callees included when it is the first to need them,
in the warm-up's order) in a fresh process with an empty cache, at numba's default
optimisation level (``NUMBA_OPT=3``) and at 1 and 0, with the part spent in LLVM (parsing,
optimising and emitting the IR numba wrote; the rest is numba's typing and lowering in
Python). ``--plain-fit`` adds the demo's warm run with the IEEE-952 fit's kernels
(fogmon/davar/scoring.py, profile.py) run as plain Python, numba's ``py_func`` (the
same code, nothing of the fit to compile): what the fit would cost without numba.

    python benchmarks/bench_first_run.py [--runs 3] [--no-aot] [--lazy] [--kernels] [--plain-fit]

Prints the load average before and after (the machine is shared).
"""
from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "replay_logs" / "lasergyro_z_100hz.csv"
ONE_HZ = ROOT / "replay_logs" / "sim_mwd_run_1hz.csv"
DBC = ROOT / "fogmon" / "data" / "gyro_example.dbc"
#: the fogmon program, optionally without the kernels compiled ahead of time (``--no-aot``) and
#: with the warm-up switched off (``--lazy``)
PROGRAM = ("import sys\nfrom fogmon import jit\njit.warm_up_on_first_use = {warm}\njit.use_ahead_of_time = {aot}\n"
           "from fogmon.cli import main\nsys.exit(main())\n")
#: the fogmon program with the fit's kernels replaced by their Python functions (``--plain-fit``)
PLAIN_FIT = """
import sys
import numba
import fogmon.davar.fit as fit, fogmon.davar.profile as profile, fogmon.davar.scoring as scoring
from fogmon import jit
for mod in (fit, profile, scoring):
    for name, f in list(vars(mod).items()):
        if isinstance(f, (numba.core.dispatcher.Dispatcher, jit.Kernel)) and f.py_func.__module__ in (profile.__name__,
                                                                                        scoring.__name__):
            setattr(mod, name, f.py_func)
from fogmon.cli import main
sys.exit(main())
"""


#: compiles every declared kernel, printing "name CPU-s LLVM-CPU-s" per kernel (numba's
#: private code-library methods timed: parse + function passes, module passes, machine code)
KERNELS = """
import time
from numba.core import codegen
from fogmon import jit
llvm = [0.0]
def timed(f):
    def g(*a, **k):
        t = time.process_time()
        try:
            return f(*a, **k)
        finally:
            llvm[0] += time.process_time() - t
    return g
for name in ("add_ir_module", "_optimize_final_module", "_finalize_final_module"):
    setattr(codegen.CPUCodeLibrary, name, timed(getattr(codegen.CPUCodeLibrary, name)))
for name, d, s in jit.declared():
    t, l0 = time.process_time(), llvm[0]
    d.compile(s)
    print(name.rsplit(".", 1)[1], time.process_time() - t, llvm[0] - l0, flush=True)
"""


def kernel_table(tmp: Path) -> None:
    """Print each declared kernel's compile CPU s (LLVM's part in parentheses) at
    ``NUMBA_OPT`` 3 (numba's default), 1 and 0, each in a fresh process and cache."""
    cols = {}
    for opt in ("3", "1", "0"):
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp / f"cache_opt{opt}"), "NUMBA_OPT": opt,
               "PYTHONPATH": str(ROOT), "PYTHONWARNINGS": "ignore"}
        p = subprocess.run([sys.executable, "-c", KERNELS], capture_output=True, text=True, env=env, cwd=ROOT)
        if p.returncode:
            raise SystemExit(f"kernel compile (NUMBA_OPT={opt}): exit {p.returncode}\n{p.stderr[-2000:]}")
        cols[opt] = [(n, float(t), float(ll)) for n, t, ll in (line.split() for line in p.stdout.splitlines())]
    print("compile CPU s per declared kernel, callees included where first needed (LLVM's part), "
          "fresh process and cache per NUMBA_OPT (0: numba cannot cache the result):")
    print(f"  {'kernel':22s}" + "".join(f" {'NUMBA_OPT=' + o:>16s}" for o in cols))
    rows = list(zip(*cols.values(), strict=True))
    for row in rows + [tuple(("total", sum(r[1] for r in c), sum(r[2] for r in c)) for c in cols.values())]:
        print(f"  {row[0][0]:22s}" + "".join(f" {t:7.2f} ({ll:5.2f})" for _, t, ll in row))


def write_can_log(path: Path, seconds: float = 600.0, rate_hz: float = 100.0) -> None:
    """A CAN log of the example gyro (fogmon/data/gyro_example.dbc): one GYRO_RATE frame per
    sample, white noise on a 10 deg/h bias, frames 5000-5029 lost."""
    import can
    import cantools

    msg = cantools.database.load_file(str(DBC)).get_message_by_name("GYRO_RATE")
    rate = 10.0 + 0.5 * np.random.default_rng(3).standard_normal(int(seconds * rate_hz))
    with can.Logger(str(path)) as log:
        for k, r in enumerate(rate):
            if 5000 <= k < 5030:
                continue
            data = msg.encode({"rate": r / 3600.0, "temperature": 20.0, "counter": k % 16, "valid": 1})
            log.on_message_received(can.Message(timestamp=1e6 + k / rate_hz, arbitration_id=msg.frame_id,
                                                is_extended_id=False, data=data))


def write_three_axis_log(path: Path, seconds: float = 1000.0, rate_hz: float = 100.0) -> None:
    """A replay log of three axes x, y, z: white noise on biases of 10, -5 and 2 deg/h."""
    from fogmon.formats.replay_log import write_replay_log

    n = int(seconds * rate_hz)
    rate = np.array([10.0, -5.0, 2.0]) + 0.5 * np.random.default_rng(4).standard_normal((n, 3))
    write_replay_log(path, np.arange(n) / rate_hz, rate, meta={"sample_rate_hz": rate_hz}, axes=("x", "y", "z"))


def hop1_ratio(runs: int) -> tuple[float, float, float, float]:
    """(push alpha=0 at hop 1, the same with every window's adev read, engine alone at
    hop 1, engine alone at hop 1024: samples per CPU s, best of ``runs`` interleaved
    repeats), as benchmarks/bench_davar.py measures them."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_davar import BLOCK, N_TAUS, WINDOW, log_taus, stream

    m = log_taus(N_TAUS, WINDOW // 4)
    y = 1000.0 + np.random.default_rng(0).normal(size=2_000_000)
    n_hop1 = WINDOW + 32 * BLOCK
    stream(y[:n_hop1], m, 1, 0)   # load the kernels
    push = read = engine1 = engine = 0.0
    for _ in range(runs):
        push = max(push, stream(y[:n_hop1], m, 1, 0))
        read = max(read, stream(y[:n_hop1], m, 1, 0, read_adev=True))
        engine1 = max(engine1, stream(y[:n_hop1], m, 1, 0, "advance"))
        engine = max(engine, stream(y, m, 1024, 0, "advance"))
    return push, read, engine1, engine


def run(args: list[str], cache: Path, warm_up: bool, program: str | None = None,
        aot: bool = True) -> tuple[float, float | None]:
    """(CPU s of ``fogmon ARGS`` in a child process with the numba cache ``cache``, the
    compile CPU s its warm-up line reports or None); ``program`` in place of the fogmon
    program, ``aot`` False: without the kernels compiled ahead of time."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run([sys.executable, "-c", program or PROGRAM.format(warm=warm_up, aot=aot), *args],
                       capture_output=True, text=True, env=env, cwd=ROOT)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode:
        raise SystemExit(f"fogmon {' '.join(args)}: exit {p.returncode}\n{p.stderr[-2000:]}")
    m = re.search(r"compiling the numba kernels once.*: done in (\d+) CPU s", p.stderr)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), float(m[1]) if m else None


def table(configs: dict[str, list[str]], cache: Path, runs: int, warm_up: bool, aot: bool = True) -> dict[str, float]:
    """Print first run / warm run per configuration (the first one first, into the empty
    cache ``cache``; ``aot`` False: without the kernels compiled ahead of time); returns
    the ratios."""
    first, compiled = {}, {}
    for name, cmd in configs.items():
        first[name], compiled[name] = run(cmd, cache, warm_up, aot=aot)
    warm: dict[str, list[float]] = {name: [] for name in configs}
    for _ in range(runs):
        for name, cmd in configs.items():
            warm[name].append(run(cmd, cache, warm_up, aot=aot)[0])
    ratios = {}
    print(f"  {'configuration':52s} {'first':>7s} {'warm':>15s} {'first/warm':>10s}  goal")
    for i, name in enumerate(configs):
        w = statistics.median(warm[name])
        ratios[name] = first[name] / w
        goal = 6.0 if i == 0 else 2.0
        note = f" (compile {compiled[name]:.0f})" if compiled[name] is not None else ""
        print(f"  {name:52s} {first[name]:7.1f} {w:6.2f} ({min(warm[name]):.2f}-{max(warm[name]):.2f}) "
              f"{ratios[name]:9.1f}x  <= {goal:g}x: {'PASS' if ratios[name] <= goal else 'FAIL'}{note}")
    return ratios


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="warm runs of each configuration (medians printed)")
    ap.add_argument("--no-aot", action="store_true",
                    help="also measure without the kernels compiled ahead of time (the first run compiles them)")
    ap.add_argument("--lazy", action="store_true",
                    help="also measure without the module compiled ahead of time and without the warm-up "
                         "(numba's lazy compiles)")
    ap.add_argument("--kernels", action="store_true",
                    help="also print each kernel's compile CPU s at NUMBA_OPT 3, 1 and 0 (LLVM's part)")
    ap.add_argument("--plain-fit", action="store_true",
                    help="also the demo's warm run with the fit's kernels run as plain Python (nothing to compile)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp_dir:
        tmp = Path(tmp_dir)
        os.environ["NUMBA_CACHE_DIR"] = str(tmp / "cache")   # before numba's import: the hop-1 ratio's cache
        can_log = tmp / "gyro.blf"
        write_can_log(can_log)
        axes_log = tmp / "axes3.csv"
        write_three_axis_log(axes_log)
        configs = {
            "README demo: replay lasergyro_z_100hz.csv --rrd": ["replay", str(DEMO), "--rrd", str(tmp / "demo.rrd")],
            "CAN replay: replay gyro.blf --dbc (10 min, 100 Hz)": ["replay", str(can_log), "--dbc", str(DBC),
                                                                   "--rrd", str(tmp / "can.rrd")],
            "replay lasergyro_z_100hz.csv --duration-s 5": ["replay", str(DEMO), "--duration-s", "5",
                                                            "--rrd", str(tmp / "d5.rrd")],
            "three axes: replay axes3.csv (100 Hz, 1000 s)": ["replay", str(axes_log), "--rrd", str(tmp / "ax.rrd")],
            "hop 1: replay lasergyro_z_100hz.csv --duration-s 30": ["replay", str(DEMO), "--duration-s", "30",
                                                                    "--window-s", "20", "--hop-s", "0.01",
                                                                    "--rrd", str(tmp / "h1.rrd")],
            "explain sim_mwd_run_1hz.csv (1 Hz, 3 h)": ["explain", str(ONE_HZ), "--report", str(tmp / "ex.json"),
                                                        "--quiet"],
        }
        from fogmon import jit

        print(f"load average {' '.join(f'{v:.1f}' for v in os.getloadavg())} (2 cores shared)")
        built = "built and current" if jit.ahead_of_time() is not None else "NOT built (or stale): numba compiles"
        print(f"first run after an empty numba cache / warm run, CPU s (warm: medians of {a.runs}, interleaved); "
              f"the first row's first run fills the cache the others start from; the kernels compiled ahead of "
              f"time: {built}:")
        table(configs, tmp / "cache", a.runs, True)
        if a.no_aot:
            print("the same without the kernels compiled ahead of time (jit.use_ahead_of_time = False):")
            table(configs, tmp / "cache_no_aot", a.runs, True, aot=False)
        if a.plain_fit:
            demo = next(iter(configs.values()))
            plain, compiled = [], []
            for _ in range(a.runs):   # interleaved
                plain.append(run(demo, tmp / "cache", True, PLAIN_FIT)[0])
                compiled.append(run(demo, tmp / "cache", True)[0])
            print(f"the README demo warm with the fit's kernels as plain Python (numba's py_func, nothing of the fit "
                  f"compiled): {statistics.median(plain):.2f} CPU s against {statistics.median(compiled):.2f} "
                  f"compiled (medians of {a.runs})")
        if a.lazy:
            print("the same without the warm-up (each kernel compiled when a run first needs it):")
            table(configs, tmp / "cache_lazy", a.runs, False, aot=False)
        if a.kernels:
            kernel_table(tmp)
        push, read, engine1, engine = hop1_ratio(a.runs)
        ratio = push / engine
        print(f"hop-1 push (alpha=0) {push / 1e6:.2f} M samples/CPU s, engine alone (advance) at hop 1024 "
              f"{engine / 1e6:.2f} M: {ratio:.3f}x  >= 0.25x: {'PASS' if ratio >= 0.25 else 'FAIL'} "
              f"(best of {a.runs}); the engine alone at hop 1 {engine1 / 1e6:.2f} M, the push "
              f"{push / engine1:.2f}x that; the push with every window's adev read (formed when read) "
              f"{read / 1e6:.2f} M: {read / engine:.3f}x")
        print(f"load average {' '.join(f'{v:.1f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
