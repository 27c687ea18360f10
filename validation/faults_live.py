"""Live devices at their limits: a fake KVH DSP-1760 in binary format A on a pty
(tests/helpers/fake_kvh.py, frame k carrying k deg/s so every sample tells which frame
it came from) against the serial source and `fogmon monitor`.

1. Throughput, at each of --rates (default 2 kHz and 4 kHz: 72 and 144 kB/s); the device
   sends --seconds s (default 20) of frames at its pace, waiting (not dropping) when the
   pty is full:
   a) the serial source alone (SerialSource.blocks() of all three axes, counted in this
      process): frames decoded of those sent, how long after the device's last frame the
      source had decoded it (must be under 1 s), how long the device waited for room (the
      reader behind), the CPU this process used (getrusage, % of one core), samples lost
      and samples off their slot (both must be 0);
   b) `fogmon monitor` (three axes, archive, console): frames archived of those sent, how
      long after the device's last frame the archive held it (it is written every 0.5 s;
      must be under 2 s), the monitor's CPU (% of one core, from /proc), every frame on
      its own slot and nothing missing.
2. An idle device: `fogmon monitor` on a pty that sends nothing, its CPU over --seconds s
   once it has opened the port (must be under 2 % of one core).
3. A counter-wrap loss: at 1 kHz the device loses runs of 128, 256 and 384 frames (1, 2
   and 3 wraps of the 7-bit counter) with no byte gap, which the counter cannot see:
   `fogmon monitor` places them by the host clock (clock_wraps 6, samples_missing 768,
   seq_gaps 3 and no other gap), every sample from CLOCK_CONFIRM_S + 0.3 s after each
   loss sits on its own slot, and the raw capture replays to the same samples and
   counters.

Prints each figure and PASS (exit code 0) when every check holds.

    python validation/faults_live.py [--seconds 20] [--rates 2000,4000] [--parts 1,2,3]
"""
from __future__ import annotations

import argparse
import math
import os
import re
import resource
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))

from helpers.fake_device import has_open, open_pty  # noqa: E402

from fogmon.formats.archive import FOLDER_PREFIX, find_pieces  # noqa: E402
from fogmon.formats.replay_log import read_replay_log  # noqa: E402
from fogmon.sources.codecs.kvh import KvhCodec  # noqa: E402
from fogmon.sources.devices.serial_port import SerialSource  # noqa: E402
from fogmon.sources.files.capture import open_raw_capture  # noqa: E402
from fogmon.sources.grid import CLOCK_CONFIRM_S  # noqa: E402

FAKE = os.path.join(ROOT, "tests", "helpers", "fake_kvh.py")
COUNT = ["--kvh-rot", "rate", "--kvh-units", "deg", "--max-rate-dph", "1e9"]
ENV = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}


class Device:
    """The fake KVH (counting frames) on a pty, waiting for ``go()``; sends ``seconds`` s of
    frames at ``rate_hz`` and stops. ``ended`` is set (host clock) when it reports the
    end: ``sent`` frames, ``waited_s`` s waiting for room in a full pty (the reader
    behind)."""

    def __init__(self, seconds: float, rate_hz: float, drops=()) -> None:
        cmd = [sys.executable, FAKE, f"{seconds:g}", "--rate-hz", f"{rate_hz:g}", "--count", "--wait",
               "--report", "1"]
        for k, n in drops:
            cmd += ["--drop", f"{k}:{n}"]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=ENV)
        self.tty = self.proc.stdout.readline().strip()  # type: ignore[union-attr]
        self.sent, self.waited_s, self.ended = 0, 0.0, 0.0
        self._thread = threading.Thread(target=self._listen, daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        for line in self.proc.stdout:  # type: ignore[union-attr]
            m = re.match(r"at [\d.]+ s: (\d+) frames written, ([\d.]+) s waited", line)
            if m:
                self.waited_s = float(m.group(2))
            m = re.match(r"sent (\d+) frames", line)
            if m:
                self.sent, self.ended = int(m.group(1)), time.monotonic()

    def go(self) -> float:
        self.proc.stdin.write("go\n")  # type: ignore[union-attr]
        self.proc.stdin.flush()  # type: ignore[union-attr]
        return time.monotonic()

    def wait_end(self, timeout_s: float) -> None:
        self._thread.join(timeout_s)

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()


def cpu_s(pid: int) -> float:
    """CPU time (user + system, s) of process ``pid`` so far."""
    with open(f"/proc/{pid}/stat") as fh:
        v = fh.read().rsplit(")", 1)[1].split()
    return (int(v[11]) + int(v[12])) / os.sysconf("SC_CLK_TCK")


def monitor(tty: str, arch: str, *extra: str) -> subprocess.Popen:
    """`fogmon monitor` archiving into a new folder in ``arch`` (made here; run_folder finds it)."""
    os.makedirs(arch, exist_ok=True)
    cmd = [sys.executable, "-m", "fogmon", "monitor", "--serial", tty, "--archive", arch, "--no-progress", *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)


def run_folder(arch: str) -> str:
    """The archive folder a monitor made in ``arch`` (``--archive arch``: a new
    fogmon-archive-* folder), or a path that does not exist before it has."""
    found = sorted(e.path for e in os.scandir(arch) if e.name.startswith(FOLDER_PREFIX))
    return found[0] if found else os.path.join(arch, "(none yet)")


def wait_for(cond, proc: subprocess.Popen, what: str, timeout_s: float = 300.0) -> None:
    """Wait until ``cond()`` (the monitor started, a file appeared), or fail."""
    end = time.monotonic() + timeout_s
    while not cond():
        if proc.poll() is not None or time.monotonic() > end:
            raise RuntimeError(f"gave up waiting for {what}: " + (proc.stderr.read() if proc.stderr else ""))
        time.sleep(0.02)


def summary_counters(out: str) -> tuple[dict[str, int], int]:
    """The counters and the sample count of a monitor's summary."""
    m = re.search(r"^\s*(\d+) samples at", out, re.M)
    counters: dict[str, int] = {}
    part = out.split("Counters:", 1)
    for line in (part[1].splitlines() if len(part) > 1 else []):
        c = re.match(r"^\s+([\w.]+)\s+(-?\d+)\s*$", line)
        if c:
            counters[c.group(1)] = int(c.group(2))
        elif line.strip() and not line.startswith(" "):
            break
    return counters, int(m.group(1)) if m else 0


def last_t(path: str) -> float:
    """Time (s) of the last whole row of a replay log being written (NaN: none yet)."""
    try:
        with open(path, "rb") as fh:
            fh.seek(max(0, os.path.getsize(path) - 8192))
            rows = [r for r in fh.read().split(b"\n")[:-1] if r and r[:1] not in b"#t"]
    except OSError:
        return float("nan")
    return float(rows[-1].split(b",")[0]) if rows else float("nan")


def archived(arch: str) -> tuple[np.ndarray, np.ndarray]:
    """(slot, frame number k) of every archived row: slot = t_s x rate, k from the z rate."""
    recs = [read_replay_log(p) for p in find_pieces(run_folder(arch), "samples.csv")]
    t = np.concatenate([r.t_s for r in recs])
    z = np.concatenate([r.rate_dph if r.rate_dph.ndim == 1 else r.rate_dph[:, -1] for r in recs])
    rate = recs[0].sample_rate_hz
    return np.rint(t * rate).astype(np.int64), np.rint(z / 3600).astype(np.int64)


class Checks:
    def __init__(self) -> None:
        self.failed: list[str] = []

    def __call__(self, name: str, ok: bool) -> None:
        if not ok:
            self.failed.append(name)
            print(f"    FAILED: {name}")


# -- 1a: the serial source alone ------------------------------------------------------------
def source_throughput(rate_hz: float, seconds: float, check: Checks) -> None:
    dev = Device(seconds, rate_hz)
    src = SerialSource(dev.tty, 921600, KvhCodec("a", "rate", "deg", None, rate_hz, 1e9))
    seen = {"n": 0, "lost": 0, "off": 0}
    done = threading.Event()

    def consume() -> None:
        for b in src.blocks():
            if len(b):
                k = np.rint(b.rate_dph[:, 2] / 3600)
                ok = b.valid.all(axis=1)
                seen["lost"] += int((~ok).sum())
                seen["off"] += int((k[ok] != np.rint(b.t_s[ok] * rate_hz)).sum())
                seen["n"] += len(b)
                if dev.sent and seen["n"] >= dev.sent:
                    done.set()

    th = threading.Thread(target=consume, daemon=True)
    th.start()
    while src._thread is None:           # the port is open (and flushed by pyserial)
        time.sleep(0.01)
    time.sleep(0.2)
    ru0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = dev.go()
    dev.wait_end(seconds + 60)
    ru1 = resource.getrusage(resource.RUSAGE_SELF)
    wall = dev.ended - t0
    done.wait(30)
    lag = time.monotonic() - dev.ended if done.is_set() else math.inf
    src.close()
    th.join(5)
    dev.close()
    cpu = (ru1.ru_utime + ru1.ru_stime - ru0.ru_utime - ru0.ru_stime) / wall
    n = seen["n"]
    print(f"  source alone: {n} of {dev.sent} frames in {wall:.1f} s ({n * 36 / wall / 1e3:.1f} kB/s), the last "
          f"decoded {lag:.2f} s after the device sent it; the device waited {dev.waited_s:.2f} s for room; CPU "
          f"{100 * cpu:.1f} % of a core; samples lost {seen['lost']}, off their slot {seen['off']}")
    check(f"source at {rate_hz:g} Hz: every frame decoded within 1 s of the device's last", lag < 1.0)
    check(f"source at {rate_hz:g} Hz: nothing lost, every sample on its slot", seen["lost"] == 0 == seen["off"])


# -- 1b: the monitor ------------------------------------------------------------------------
def monitor_throughput(rate_hz: float, seconds: float, work: str, check: Checks) -> None:
    dev = Device(seconds, rate_hz)
    arch = os.path.join(work, f"arch-{rate_hz:g}")
    mon = monitor(dev.tty, arch, "--rate-hz", f"{rate_hz:g}", *COUNT)
    try:
        wait_for(lambda: os.path.exists(os.path.join(run_folder(arch), "raw-0001.bin")), mon, "the monitor to start")
        csv = os.path.join(run_folder(arch), "samples-0001.csv")
        c0, t0 = cpu_s(mon.pid), dev.go()
        dev.wait_end(seconds + 60)
        c1, wall = cpu_s(mon.pid), dev.ended - t0
        end = time.monotonic() + 60
        while not last_t(csv) >= (dev.sent - 1.5) / rate_hz and time.monotonic() < end and mon.poll() is None:
            time.sleep(0.05)
        lag = time.monotonic() - dev.ended if last_t(csv) >= (dev.sent - 1.5) / rate_hz else math.inf
        mon.terminate()
        out, err = mon.communicate(timeout=600)
    finally:
        if mon.poll() is None:
            mon.kill()
        dev.close()
    counters, n = summary_counters(out)
    slot, k = archived(arch)
    print(f"  fogmon monitor: {len(k)} of {dev.sent} frames archived, the last {lag:.2f} s after the device sent it "
          f"(the archive is written every 0.5 s); the device waited {dev.waited_s:.2f} s for room; CPU "
          f"{100 * (c1 - c0) / wall:.1f} % of a core; samples_missing {counters.get('samples_missing')}, "
          f"rc {mon.returncode}")
    if mon.returncode:
        print("   ", err.strip().splitlines()[-1] if err.strip() else "(no stderr)")
    check(f"monitor at {rate_hz:g} Hz: every frame archived within 2 s of the device's last", lag < 2.0)
    check(f"monitor at {rate_hz:g} Hz: every frame archived on its slot",
          mon.returncode == 0 and np.array_equal(k, np.arange(dev.sent)) and np.array_equal(slot, k)
          and counters.get("samples_missing") == 0)


# -- 2: idle ----------------------------------------------------------------------------------
def idle(seconds: float, work: str, check: Checks) -> None:
    master, slave, tty = open_pty()
    mon = monitor(tty, os.path.join(work, "arch-idle"), "--quiet")
    try:
        wait_for(lambda: has_open(mon.pid, tty), mon, "the monitor to open the port")
        time.sleep(2.0)
        c0, t0 = cpu_s(mon.pid), time.monotonic()
        time.sleep(seconds)
        c1, wall = cpu_s(mon.pid), time.monotonic() - t0
    finally:
        mon.terminate()
        mon.communicate(timeout=120)
        os.close(master)
        os.close(slave)
    cpu = (c1 - c0) / wall
    print(f"  idle fogmon monitor (the device sends nothing): CPU {100 * cpu:.2f} % of a core over {wall:.1f} s")
    check("idle monitor under 2 % of a core", cpu < 0.02)


# -- 3: a counter-wrap loss ------------------------------------------------------------------
DROPS = ((2000, 128), (5000, 256), (8000, 384))


def wrap_loss(work: str, check: Checks) -> None:
    rate_hz, seconds = 1000.0, 11.0
    dev = Device(seconds + 30, rate_hz, DROPS)
    arch = os.path.join(work, "arch-wraps")
    mon = monitor(dev.tty, arch, "--axis", "z", *COUNT, "--duration-s", f"{seconds:g}")
    try:
        wait_for(lambda: os.path.exists(os.path.join(run_folder(arch), "raw-0001.bin")), mon, "the monitor to start")
        dev.go()
        out, err = mon.communicate(timeout=600)
    finally:
        if mon.poll() is None:
            mon.kill()
        dev.close()
    counters, n = summary_counters(out)
    slot, k = archived(arch)
    lost = sum(m for _, m in DROPS)
    kept = np.ones(n, bool)
    for k0, m in DROPS:
        kept[k0:k0 + m] = False
    settle = int((CLOCK_CONFIRM_S + 0.3) * rate_hz)
    settled = np.ones(len(k), bool)
    for k0, m in DROPS:
        settled &= ~((k >= k0 + m) & (k < k0 + m + settle))
    on_slot = int((slot[settled] == k[settled]).sum())
    gaps = [ln for ln in err.splitlines() if "gap" in ln and "lost at" in ln]
    print(f"  lost without a byte gap: {', '.join(f'{m} frames at frame {k0}' for k0, m in DROPS)}; monitor: "
          f"clock_wraps {counters.get('clock_wraps')}, samples_missing {counters.get('samples_missing')}, "
          f"seq_gaps {counters.get('seq_gaps')}; {len(k)} rows archived ({int(kept[:n].sum())} frames sent in the "
          f"run), {on_slot} of {int(settled.sum())} settled rows on their slot")
    for g in gaps:
        print("   ", g.strip())
    check("monitor exit code 0", mon.returncode == 0)
    check("clock_wraps == 6, samples_missing == 768, seq_gaps == 3",
          (counters.get("clock_wraps"), counters.get("samples_missing"), counters.get("seq_gaps")) == (6, lost, 3))
    check("every frame sent in the run archived", np.array_equal(k, np.flatnonzero(kept[:n])))
    check(f"every row from {CLOCK_CONFIRM_S + 0.3:g} s after a loss on its slot", on_slot == int(settled.sum()))
    replay = open_raw_capture(find_pieces(run_folder(arch), "raw.bin"))
    blocks = list(replay.blocks())
    vt = np.concatenate([b.t_s[b.valid] for b in blocks])
    keys = ("frames_ok", "seq_gaps", "samples_missing", "clock_wraps", "implausible_gaps")
    diff = {x: (counters.get(x), replay.counters.get(x)) for x in keys if counters.get(x) != replay.counters.get(x)}
    print(f"  raw capture replayed: {sum(len(b) for b in blocks)} samples, counters differing: {diff or 'none'}")
    check("raw capture replays to the same samples and counters",
          np.array_equal(np.rint(vt * rate_hz).astype(np.int64), slot) and not diff)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="length of each throughput and idle run, s")
    ap.add_argument("--rates", default="2000,4000", help="device rates for the throughput runs, Hz")
    ap.add_argument("--parts", default="1,2,3", help="which parts to run (1 throughput, 2 idle, 3 wrap loss)")
    args = ap.parse_args(argv)
    parts = {p.strip() for p in args.parts.split(",")}
    check = Checks()
    with tempfile.TemporaryDirectory(prefix="fogmon-faults-live-") as work:
        if "1" in parts:
            for rate in (float(r) for r in args.rates.split(",")):
                print(f"1. KVH format A at {rate:g} Hz ({rate * 36 / 1e3:g} kB/s), {args.seconds:g} s")
                source_throughput(rate, args.seconds, check)
                monitor_throughput(rate, args.seconds, work, check)
        if "2" in parts:
            print(f"2. an idle device, {args.seconds:g} s")
            idle(args.seconds, work, check)
        if "3" in parts:
            print("3. whole counter wraps lost without a byte gap (1 kHz)")
            wrap_loss(work, check)
    print(f"faults_live: {'PASS' if not check.failed else 'FAIL (' + '; '.join(check.failed) + ')'}")
    return 0 if not check.failed else 1


if __name__ == "__main__":
    sys.exit(main())
