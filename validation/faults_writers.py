"""Every writer fault of issues 31.1 and 32 (items 1, 5, 8), driven as a user meets it.

- A full disk: a small tmpfs (when this process may mount one, e.g. as root; else every
  command runs under a file-size limit, RLIMIT_FSIZE: both are real write failures).
  `fogmon monitor` of a fake 1 kHz KVH DSP-1760 (pty) into an archive that fills the
  disk (CSV and Parquet): exit 1, its summary printed and saying why, one line naming
  the file and the free space, no traceback, the archive replays (its samples and its
  raw capture); `replay --rrd`: the .rrd removed, exit 2 after the summary; `sim`,
  `convert`, `explain`, `fit --export`, `batch`: exit 2, one line, no file or .tmp left,
  no 0-byte report.
- Two writers on one archive folder (two processes): the second gets one line naming
  the first's pid; the lock of a SIGKILLed writer is free again. Two monitors with one
  `--archive DIR` each make their own time-stamped archive folder.
- Outputs against inputs: for every command that writes, the output as the input, as a
  symlink to it, as rotation pieces over it, as an archive piece, in a missing folder:
  exit 2, one line, the input unchanged, nothing created.
- sim: N = 1e308 (non-finite output) refused; `--out x.parquet` is Parquet, `x.txt` refused.
- batch: one unreadable input among good ones (exit 2, the rest written); a scheduler
  with no worker and one whose only worker is killed mid-run (an error, not a wait);
  Ctrl-C to the process group (exit 130, no traceback).
- Measured: bytes per archived row (samples and raw capture) of the monitor, and bytes
  per row of `fogmon sim` (what the free-space checks use; docs/monitor.md quotes them).

Prints each check and PASS (exit 0) only when all pass.

    python validation/faults_writers.py [--seconds 20] [--keep]
"""
from __future__ import annotations

import argparse
import contextlib
import hashlib
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

from fogmon.formats.archive import FOLDER_PREFIX  # noqa: E402
from fogmon.formats.replay_log import write_replay_log  # noqa: E402

FAKE_KVH = ROOT / "tests" / "helpers" / "fake_kvh.py"
MODEL = ROOT / "fogmon" / "data" / "example_model.toml"
DEMO = ROOT / "replay_logs" / "lasergyro_z_100hz.csv"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
FOGMON = [sys.executable, "-m", "fogmon"]

RESULTS: list[tuple[str, bool, str]] = []


def check(name: str, ok: bool, detail: str = "") -> bool:
    RESULTS.append((name, bool(ok), detail))
    print(f"  [{'ok' if ok else 'FAIL'}] {name}" + (f"  ({detail})" if detail and not ok else ""), flush=True)
    return bool(ok)


def one_line_error(err: str, prefix: str) -> bool:
    """The last stderr line is the error and no traceback was printed."""
    lines = err.strip().splitlines()
    return bool(lines) and lines[-1].startswith(prefix) and "Traceback" not in err


def digest(folder: Path) -> dict[str, str]:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() and not p.is_symlink() else "-"
            for p in sorted(folder.rglob("*"))}


def archive_in(parent: Path) -> Path | None:
    found = sorted(parent.glob(FOLDER_PREFIX + "*"))
    return found[0] if found else None


# -- a small disk ---------------------------------------------------------------------
class SmallDisk:
    """A folder on a small tmpfs of ``size`` bytes, or (when no tmpfs can be mounted) a
    plain folder whose writers run under RLIMIT_FSIZE = ``size``."""

    def __init__(self, base: Path, size: int) -> None:
        self.folder = base / "disk"
        self.folder.mkdir()
        self.size = size
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(self.folder)],
                           capture_output=True, text=True)
        self.tmpfs = r.returncode == 0
        self.how = (f"tmpfs of {size // 1024} kB" if self.tmpfs else
                    f"file-size limit (RLIMIT_FSIZE) of {size // 1024} kB (no tmpfs: {r.stderr.strip() or 'mount'})")

    def limit(self) -> None:     # preexec_fn of the commands under test
        if not self.tmpfs:
            resource.setrlimit(resource.RLIMIT_FSIZE, (self.size, self.size))

    def run(self, argv: list[str], timeout: float = 900, **kw) -> subprocess.CompletedProcess:
        return subprocess.run([*FOGMON, *argv], capture_output=True, text=True, env=ENV, timeout=timeout,
                              preexec_fn=self.limit, **kw)

    def run_full(self, argv: list[str]) -> subprocess.CompletedProcess:
        """``fogmon ARGV`` on the disk filled up (tmpfs), or (file-size limit) with no
        file allowed to grow from its first output write on (not earlier: the imports'
        caches would fail first)."""
        if self.tmpfs:
            return self.run(argv)
        code = ("import contextlib, resource, sys\nimport fogmon.outputs as o\n_w = o.written\n"
                "@contextlib.contextmanager\ndef written(*a, **k):\n"
                "    resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))\n"
                "    with _w(*a, **k) as t:\n        yield t\n"
                f"o.written = written\nfrom fogmon.cli import main\nsys.exit(main({argv!r}))\n")
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=900)

    def fill(self, leave: int) -> None:
        """Fill the disk up to ``leave`` bytes (tmpfs; under a file-size limit every file
        is small anyway)."""
        if self.tmpfs:
            with open(self.folder / "filler", "wb") as fh, contextlib.suppress(OSError):
                while shutil.disk_usage(self.folder).free > leave:
                    fh.write(b"\0" * min(65536, max(1, shutil.disk_usage(self.folder).free - leave)))
                    fh.flush()

    def clean(self) -> None:
        for p in self.folder.iterdir():
            shutil.rmtree(p) if p.is_dir() else p.unlink()

    def close(self) -> None:
        if self.tmpfs:
            subprocess.run(["umount", str(self.folder)], check=False)


def fake_kvh(seconds: float) -> tuple[subprocess.Popen, str]:
    dev = subprocess.Popen([sys.executable, str(FAKE_KVH), str(seconds)], stdout=subprocess.PIPE, text=True)
    assert dev.stdout is not None
    return dev, dev.stdout.readline().strip()


def monitor(port: str, archive: Path, *extra: str, preexec=None, seconds: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([*FOGMON, "monitor", "--serial", port, "--protocol", "kvh-a", "--archive", str(archive),
                           "--window-s", "2.048", "--no-progress", "--duration-s", str(seconds), *extra],
                          capture_output=True, text=True, env=ENV, timeout=seconds + 600, preexec_fn=preexec)


# -- the faults -----------------------------------------------------------------------
def disk_full(work: Path) -> None:
    print("A full disk")
    disk = SmallDisk(work, 256 * 1024)
    print(f"  ({disk.how})")
    try:
        for fmt in ("csv", "parquet"):
            dev, port = fake_kvh(200)
            try:
                p = monitor(port, disk.folder, "--archive-format", fmt, preexec=disk.limit, seconds=120)
            finally:
                dev.kill()
                dev.wait()
            arch = archive_in(disk.folder)
            check(f"monitor ({fmt} archive): exit 1 with one line naming the file and the free space",
                  p.returncode == 1 and one_line_error(p.stderr, "fogmon monitor: error: --archive ")
                  and "cannot write: " in p.stderr and " free in " in p.stderr, p.stderr[-600:])
            check(f"monitor ({fmt}): the summary is printed and says why it stopped",
                  "Overall Allan deviation" in p.stdout and ("fogmon: stopped (the archive could not write: --archive"
                                                              in p.stdout or fmt == "parquet"), p.stdout[-400:])
            left = [x.name for x in arch.rglob("*") if x.name.endswith(".tmp")] if arch else ["no archive"]
            check(f"monitor ({fmt}): no .tmp left", not left, str(left))
            r = subprocess.run([*FOGMON, "replay", str(arch), "--window-s", "2.048", "--no-progress", "--quiet"],
                               capture_output=True, text=True, env=ENV, timeout=600)
            check(f"monitor ({fmt}): the archive replays (whole rows)", r.returncode == 0, r.stderr[-400:])
            r = subprocess.run([*FOGMON, "replay", str(arch), "--protocol", "kvh-a", "--window-s", "2.048",
                                "--no-progress", "--quiet"], capture_output=True, text=True, env=ENV, timeout=600)
            check(f"monitor ({fmt}): its raw capture replays", r.returncode == 0, r.stderr[-400:])
            disk.clean()

        rrd = disk.folder / "demo.rrd"
        p = disk.run(["replay", str(DEMO), "--rrd", str(rrd), "--no-progress"])
        check("replay --rrd: exit 2 after the summary, the .rrd removed with a warning",
              p.returncode == 2 and "Overall Allan deviation" in p.stdout and not rrd.exists()
              and f"fogmon: warning: {rrd}: Rerun could not complete it" in p.stderr
              and one_line_error(p.stderr, f"fogmon replay: error: --rrd {rrd}: cannot write: "), p.stderr[-600:])
        disk.clean()

        for suffix in (".csv", ".parquet"):
            out = disk.folder / f"sim{suffix}"
            p = disk.run(["sim", "--model", str(MODEL), "--duration-s", "100000", "--seed", "1", "--out", str(out)])
            check(f"sim {suffix}: exit 2, one line naming the file and the free space (the free-space check or the "
                  f"write that failed), nothing left",
                  p.returncode == 2 and p.stderr.count("\n") == 1
                  and p.stderr.startswith(f"fogmon sim: error: --out {out}: ") and " free in " in p.stderr
                  and not list(disk.folder.iterdir()), p.stderr[-400:])
            disk.clean()

        out = disk.folder / "demo.parquet"
        p = disk.run(["convert", str(DEMO), str(out)])
        check("convert: exit 2, one line (the free-space check, or the write that failed), no .parquet or .tmp left",
              p.returncode == 2 and p.stderr.count("\n") == 1 and f"OUT {out}: " in p.stderr and " free in " in p.stderr
              and not list(disk.folder.iterdir()), p.stderr[-400:])
        disk.clean()

        rec = work / "explain.csv"
        n = 4000
        write_replay_log(rec, np.arange(n) / 10.0, np.random.default_rng(2).standard_normal(n), None,
                         {"sample_rate_hz": 10})
        disk.fill(leave=0)
        report = disk.folder / "r.json"
        p = disk.run_full(["explain", str(rec), "--report", str(report), "--bootstrap", "8", "--max-effects", "0",
                           "--quiet"])
        check("explain on a full disk: exit 2, one line, no 0-byte report",
              p.returncode == 2 and one_line_error(p.stderr, f"fogmon explain: error: --report {report}: cannot write")
              and not report.exists() and not list(disk.folder.glob(".*")), p.stderr[-400:])
        curve = work / "curve.csv"
        curve.write_text("tau_s,adev_dph\n" + "".join(f"{2.0 ** k!r},{1.0 / 2 ** (k / 2)!r}\n" for k in range(8)))
        yaml = disk.folder / "imu.yaml"
        p = disk.run_full(["fit", str(curve), "--export", "kalibr", str(yaml)])
        check("fit --export on a full disk: exit 2, one line, no file",
              p.returncode == 2 and one_line_error(p.stderr, f"fogmon fit: error: --export kalibr {yaml}: cannot write")
              and not yaml.exists(), p.stderr[-400:])
        disk.clean()
        if disk.tmpfs:
            logs = work / "fleet-in"
            logs.mkdir()
            for i in range(2):
                write_replay_log(logs / f"g{i}.csv", np.arange(60_000) / 100.0,
                                 np.random.default_rng(i).standard_normal(60_000), None, {"sample_rate_hz": 100})
            disk.fill(leave=4096)
            out = disk.folder / "fleet"
            p = disk.run(["batch", str(logs), "--out", str(out), "--workers", "1", "--no-progress"])
            check("batch on a full disk: exit 2, one line, no .tmp left",
                  p.returncode == 2 and one_line_error(p.stderr, "fogmon batch: error: --out ")
                  and not [x for x in disk.folder.rglob("*") if ".tmp" in x.name], p.stderr[-400:])
            disk.clean()
    finally:
        disk.close()


def two_writers(work: Path, seconds: float) -> None:
    print("Two writers, one archive")
    folder = work / "locked"
    holder = subprocess.Popen([sys.executable, "-c",
                               "import sys\nfrom fogmon.sinks.archive import Archive\n"
                               "class S:\n    name, sample_rate_hz, counters, axes = 'gyro', 10.0, {}, ()\n"
                               f"a = Archive({str(folder)!r}, S())\nprint('ready', flush=True)\nsys.stdin.read()\n"],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=ENV)
    assert holder.stdout is not None and holder.stdout.readline() == "ready\n"
    second = ("import sys\nfrom fogmon.errors import FogmonError\nfrom fogmon.sinks.archive import Archive\n"
              "class S:\n    name, sample_rate_hz, counters, axes = 'gyro', 10.0, {}, ()\n"
              f"try:\n    Archive({str(folder)!r}, S()).close()\nexcept FogmonError as e:\n"
              "    print(e); sys.exit(2)\nprint('written')\n")
    p = subprocess.run([sys.executable, "-c", second], capture_output=True, text=True, env=ENV)
    check("a second writer on the folder: one line naming the first's pid",
          p.returncode == 2 and f"another fogmon (pid {holder.pid} on " in p.stdout and not p.stderr,
          p.stdout + p.stderr)
    holder.kill()
    holder.wait()
    p = subprocess.run([sys.executable, "-c", second], capture_output=True, text=True, env=ENV)
    check("the lock of a writer killed with SIGKILL is free again", p.returncode == 0 and "written" in p.stdout,
          p.stdout + p.stderr)
    runs = work / "runs"
    runs.mkdir()
    devs = [fake_kvh(seconds + 120) for _ in range(2)]
    try:
        procs = [subprocess.Popen([*FOGMON, "monitor", "--serial", port, "--protocol", "kvh-a", "--axis", "z",
                                   "--archive", str(runs), "--duration-s", str(seconds), "--window-s", "2.048",
                                   "--no-progress", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True, env=ENV) for _, port in devs]
        outs = [pr.communicate(timeout=seconds + 600) for pr in procs]
    finally:
        for dev, _ in devs:
            dev.kill()
            dev.wait()
    folders = sorted(runs.glob(FOLDER_PREFIX + "*"))
    ok = [pr.returncode for pr in procs] == [0, 0] and len(folders) == 2
    lock_msg = [e for _, e in outs if "is writing an archive there" in e]
    check("two monitors with one --archive DIR: each its own time-stamped archive folder (or, started in the same "
          "second, the second gets the lock's one line)", ok or (len(lock_msg) == 1 and len(folders) == 1),
          f"exit codes {[pr.returncode for pr in procs]}, folders {[f.name for f in folders]}, "
          f"{[e[-200:] for _, e in outs]}")


def outputs_against_inputs(work: Path) -> None:
    print("Outputs never touch inputs")
    d = work / "same"
    d.mkdir()
    rec, model, curve = d / "rec.csv", d / "model.toml", d / "curve.csv"
    n = 2000
    write_replay_log(rec, np.arange(n) / 10.0, np.random.default_rng(1).standard_normal(n),
                     {"temp_c": 20 + np.arange(n) / 1000}, {"sample_rate_hz": 10})
    shutil.copy(MODEL, model)
    curve.write_text("tau_s,adev_dph\n" + "".join(f"{2.0 ** k!r},{1.0 / 2 ** (k / 2)!r}\n" for k in range(8)))
    arch = d / "arch"
    arch.mkdir()
    write_replay_log(arch / "samples-0001.csv", np.arange(n) / 10.0, np.zeros(n), meta={"sample_rate_hz": 10})
    runs = d / "runs"
    runs.mkdir()
    commands = {   # command -> argv writing OUT
        "replay": ["replay", str(rec), "--rrd", "OUT"],
        "monitor": ["monitor", "--serial", str(d / "no-port"), "--protocol", "kvh-a", "--dbc", str(rec),
                    "--archive", str(runs), "--rrd", "OUT"],
        "sim": ["sim", "--model", str(model), "--like", str(rec), "--out", "OUT"],
        "explain": ["explain", str(rec), "--report", "OUT"],
        "fit": ["fit", str(curve), "--export", "kalibr", "OUT"],
        "convert": ["convert", str(rec), "OUT"],
        "batch": ["batch", str(rec), "--out", str(d / "fleet"), "--report", "OUT"],
        "thermal": ["thermal", str(rec), "--out-corrected", "OUT"],
    }
    for command, argv in commands.items():
        read = curve if command == "fit" else rec
        link = d / f"link-to-{read.name}"
        if not link.is_symlink():
            link.symlink_to(read)
        cases = {"the input": str(read), "a symlink to the input": str(link),
                 "an archive piece": str(arch / "samples-0002.csv"), "in a missing folder": str(d / "no" / "x.csv")}
        for what, out in cases.items():
            before = digest(d)
            p = subprocess.run([*FOGMON, *[out if a == "OUT" else a for a in argv]], capture_output=True,
                               text=True, env=ENV, timeout=300)
            check(f"{command}: output {what}: exit 2, one line, nothing changed or created",
                  p.returncode == 2 and p.stderr.count("\n") == 1 and digest(d) == before, p.stderr[-300:])
    for command in ("replay", "monitor"):
        piece = d / "rec-0001.csv"
        shutil.copy(rec, piece)
        argv = [str(piece) if a == str(rec) else a for a in commands[command]]
        before = digest(d)
        p = subprocess.run([*FOGMON, *[str(rec) if a == "OUT" else a for a in argv], "--rotate-s", "60"],
                           capture_output=True, text=True, env=ENV, timeout=300)
        check(f"{command}: --rotate-s pieces over an input: exit 2, one line, nothing changed",
              p.returncode == 2 and "would overwrite the input" in p.stderr and digest(d) == before, p.stderr[-300:])
        piece.unlink()
    p = subprocess.run([*FOGMON, "replay", str(rec), "--rrd", "/fogmon-no-such-folder/x.rrd"], capture_output=True,
                       text=True, env=ENV, timeout=300)
    check("--rrd /nonexistent/x.rrd: refused, no folder made at the root",
          p.returncode == 2 and not os.path.exists("/fogmon-no-such-folder"), p.stderr[-300:])
    out = d / "live.rrd"
    dev, port = fake_kvh(120)
    try:
        p = monitor(port, runs, "--axis", "z", "--rrd", str(out), seconds=3)
    finally:
        dev.kill()
        dev.wait()
    check("monitor --rrd X writes X itself (pieces only with --rotate-s); --archive DIR makes DIR/fogmon-archive-*",
          p.returncode == 0 and out.exists() and not (d / "live-0001.rrd").exists() and archive_in(runs) is not None,
          p.stderr[-300:])


def sim_outputs(work: Path) -> float:
    print("sim: non-finite output, suffixes, bytes per row")
    d = work / "sim"
    d.mkdir()
    model = d / "m.toml"
    model.write_text("[sensor]\nsample_rate_hz = 10.0\nbias_dph = 0.0\n[noise]\nQ_arcsec = 0.0\nN_dpsh = 1e308\n"
                     "B_dph = 0.0\nK_dphsh = 0.0\nR_dphh = 0.0\n")
    p = subprocess.run([*FOGMON, "sim", "--model", str(model), "--out", str(d / "o.csv"), "--duration-s", "10"],
                       capture_output=True, text=True, env=ENV)
    check("sim with N 1e308: exit 2, one line, nothing written",
          p.returncode == 2 and p.stderr.count("\n") == 1 and "not finite" in p.stderr and not (d / "o.csv").exists(),
          p.stderr)
    p = subprocess.run([*FOGMON, "sim", "--model", str(MODEL), "--out", str(d / "o.parquet"), "--duration-s", "60",
                        "--seed", "1"], capture_output=True, text=True, env=ENV)
    check("sim --out x.parquet writes Parquet",
          p.returncode == 0 and (d / "o.parquet").read_bytes()[:4] == b"PAR1", p.stderr)
    p = subprocess.run([*FOGMON, "sim", "--model", str(MODEL), "--out", str(d / "o.txt"), "--duration-s", "60"],
                       capture_output=True, text=True, env=ENV)
    check("sim --out x.txt refused", p.returncode == 2 and not (d / "o.txt").exists(), p.stderr)
    out = d / "hour.csv"
    subprocess.run([*FOGMON, "sim", "--model", str(MODEL), "--out", str(out), "--duration-s", "3600", "--seed", "1"],
                   capture_output=True, text=True, env=ENV, check=True)
    lines = out.read_text().splitlines(keepends=True)
    data = [line for line in lines if line[:1].isdigit() or line[:1] == "-"]
    per_row = sum(len(line) for line in data) / len(data)
    print(f"  measured: fogmon sim of {MODEL.name} (100 Hz, rate only): {per_row:.1f} bytes per CSV row")
    return per_row


def batch_faults(work: Path) -> None:
    print("batch: unreadable inputs, no workers, Ctrl-C")
    d = work / "batch"
    (d / "in").mkdir(parents=True)
    for i in range(3):
        write_replay_log(d / "in" / f"g{i}.csv", np.arange(60_000) / 100.0,
                         np.random.default_rng(i).standard_normal(60_000), None, {"sample_rate_hz": 100})
    (d / "in" / "bad.csv").write_text("# fogmon replay log v1\ntime_s,rate_dph\n0,1\n0.01,x\n")
    p = subprocess.run([*FOGMON, "batch", str(d / "in"), "--out", str(d / "out"), "--workers", "2", "--no-progress"],
                       capture_output=True, text=True, env=ENV, timeout=900)
    import pyarrow.parquet as pq
    rows = pq.read_table(d / "out" / "recordings.parquet").to_pylist() if (d / "out").exists() else []
    check("one unreadable input among good ones: exit 2 naming it, the rest analysed and written",
          p.returncode == 2 and "bad.csv: line 4" in p.stderr and "Traceback" not in p.stderr
          and sum(1 for r in rows if not r["error"]) == 3 and sum(1 for r in rows if r["error"]) == 1,
          p.stderr[-400:])

    import fogmon.cli.batch as batch
    from fogmon.cli import main
    batch.NO_WORKER_S, batch.POLL_S = 5.0, 0.5
    from distributed import LocalCluster
    with LocalCluster(n_workers=0, processes=False, dashboard_address=None) as cluster:
        t0 = time.monotonic()
        rc = main(["batch", str(d / "in" / "g0.csv"), "--out", str(d / "o2"), "--scheduler",
                   cluster.scheduler_address, "--no-progress"])
        check("a scheduler without workers: an error within NO_WORKER_S, not a wait", rc == 2
              and time.monotonic() - t0 < 60 and not (d / "o2").exists())

    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    dask = str(Path(sys.executable).parent / "dask")
    sched = subprocess.Popen([dask, "scheduler", "--port", str(port), "--no-dashboard"], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, env=ENV)
    worker = subprocess.Popen([dask, "worker", addr, "--nthreads", "1", "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV)
    try:
        from distributed import Client
        with Client(addr, timeout=60) as c:
            c.wait_for_workers(1, timeout=120)

        def kill_when_busy():
            with Client(addr, timeout=60) as c:
                while not c.processing() or not any(c.processing().values()):
                    time.sleep(0.05)
            worker.kill()

        killer = threading.Thread(target=kill_when_busy, daemon=True)
        killer.start()
        big = d / "big.csv"
        write_replay_log(big, np.arange(2_000_000) / 100.0, np.random.default_rng(9).standard_normal(2_000_000), None,
                         {"sample_rate_hz": 100})
        t0 = time.monotonic()
        rc = main(["batch", str(big), "--out", str(d / "o3"), "--scheduler", addr, "--no-progress"])
        check("its only worker killed mid-run: an error after NO_WORKER_S, not a wait",
              rc == 2 and time.monotonic() - t0 < 300 and not (d / "o3").exists())
    finally:
        for proc in (worker, sched):
            proc.kill()
            proc.wait()

    more = d / "many"
    more.mkdir()
    for i in range(24):
        write_replay_log(more / f"r{i}.csv", np.arange(300_000) / 100.0,
                         np.random.default_rng(i).standard_normal(300_000), None, {"sample_rate_hz": 100})
    for delay in (4.0, 12.0):
        p = subprocess.Popen([*FOGMON, "batch", str(more), "--out", str(d / f"o-int-{delay:g}"), "--workers", "2",
                              "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
                             start_new_session=True)
        time.sleep(delay)
        os.killpg(p.pid, signal.SIGINT)          # what a terminal's Ctrl-C does: the whole process group
        _, err = p.communicate(timeout=300)
        check(f"Ctrl-C to the process group after {delay:g} s: exit 130, no traceback",
              p.returncode == 130 and "Traceback" not in err and "Task exception" not in err
              and re.search(r"interrupted \(Ctrl-C\)", err) is not None, err[-600:])


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def bytes_per_row(work: Path, seconds: float) -> None:
    print(f"Measured: bytes per archived row, fake KVH DSP-1760 format A at 1 kHz, {seconds:g} s")
    for label, extra in (("one axis (--axis z), CSV", ["--axis", "z"]), ("three axes + accelerometers, CSV", []),
                         ("three axes + accelerometers, Parquet", ["--archive-format", "parquet"])):
        runs = work / f"bpr-{len(extra)}-{label[:3]}"
        runs.mkdir()
        dev, port = fake_kvh(seconds + 120)
        try:
            p = monitor(port, runs, *extra, "--quiet", seconds=seconds)
        finally:
            dev.kill()
            dev.wait()
        arch = archive_in(runs)
        if p.returncode != 0 or arch is None:
            check(f"measure {label}", False, p.stderr[-300:])
            continue
        samples = sum(x.stat().st_size for x in arch.glob("samples-*"))
        raw = sum(x.stat().st_size for x in arch.glob("raw-*.bin"))
        from fogmon.sources.open import open_replay_source
        rows = sum(int(b.valid.all(axis=1).sum() if b.axes else b.valid.sum()) for b in
                   open_replay_source(str(arch), None).blocks())
        print(f"  {label}: {rows} rows; samples {samples / rows:.1f} B/row, raw capture {raw / rows:.1f} B/row, "
              f"together {(samples + raw) / rows:.1f} B/row = {(samples + raw) / rows * 86400e3 / 1e9:.2f} GB per day")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="monitor runs for the measurement, s (default 20)")
    ap.add_argument("--keep", action="store_true", help="keep the work folder")
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="fogmon-faults-writers-"))
    try:
        disk_full(work)
        two_writers(work, 3.0)
        outputs_against_inputs(work)
        sim_outputs(work)
        batch_faults(work)
        bytes_per_row(work, args.seconds)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
        else:
            print(f"work folder kept: {work}")
    failed = [name for name, ok, _ in RESULTS if not ok]
    print(f"\n{len(RESULTS) - len(failed)} of {len(RESULTS)} checks passed")
    print("PASS" if not failed else "FAIL: " + "; ".join(failed))
    return 0 if not failed else 1


if __name__ == "__main__":
    sys.exit(main())
