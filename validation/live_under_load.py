"""The live path on a busy machine: `fogmon monitor` against a fake KVH DSP-1760 on a pty.

The fake device sends binary Format A frames at 1 kHz in rate mode (deg/s); frame k
carries k x 0.001 deg/s on the z axis, so every archived sample tells which frame it came
from (k = rate_dph / 3.6) and where on the time base it belongs (t_s = k / 1000). Seeded
faults: dropped frames (runs of 1-3, the device's counter jumps), corrupted frames (a
flipped byte: CRC failure), truncated frames (bytes lost), garbage bytes between frames;
and stalls of 10 ms to 2 s (log-uniform): the sender stalls (its frames go out late, in a
burst; none is lost) or the monitor's host is stalled (SIGSTOP ... SIGCONT of the monitor
process), or both; two CPU hogs run beside it all the time. The monitor runs
`--duration-s` s three times: plain, with `--rrd`, and with `--connect` to a headless
`rerun --serve-grpc` started and killed here. For each run it prints

- valid frames sent / archived (frames sent intact inside the run; must be equal and be
  the same frames),
- phantom gaps (samples reported lost that were not: must be 0) and missed losses,
- time-base error (largest |t_s x 1000 - k| over the archive, in samples: must be 0),
- counters against the injected faults, against the events (the .rrd's event log) and
  against the raw capture decoded again (same samples as samples-NNNN.csv, same counters),
  and no outage in the capture's sidecar (the port is never reopened),

and PASS/FAIL. Exit code 0 when every run passes.

    python validation/live_under_load.py [--duration-s 60] [--seed 1] [--hogs 2] [--modes plain,rrd,connect]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import signal
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

from fogmon.errors import FogmonError  # noqa: E402
from fogmon.formats.archive import FOLDER_PREFIX, find_pieces  # noqa: E402
from fogmon.formats.replay_log import read_replay_log  # noqa: E402
from fogmon.sources.codecs.kvh import encode_frame  # noqa: E402
from fogmon.sources.files.capture import open_raw_capture  # noqa: E402

RATE_HZ = 1000
DPS_PER_K = 1e-3            # frame k sends k x 0.001 deg/s = 3.6 k deg/h
P_DROP, P_CORRUPT, P_TRUNCATE, P_GARBAGE = 0.002, 0.002, 0.0005, 0.001
STALL_MIN_S, STALL_MAX_S = 0.01, 2.0


def frame(k: int) -> bytes:
    return encode_frame("a", k % 128, (0.0, 0.0, k * DPS_PER_K), temp_c=25)


class Plan:
    """The seeded faults of frames 0..n-1 and the stall schedule."""

    def __init__(self, n: int, duration_s: float, rng: np.random.Generator) -> None:
        self.fault = np.zeros(n, np.int8)      # 0 intact, 1 dropped, 2 corrupted, 3 truncated
        u = rng.random(n)
        k = 0
        while k < n:
            if u[k] < P_DROP:
                run = int(rng.integers(1, 4))
                self.fault[k:k + run] = 1
                k += run
                continue
            if u[k] < P_DROP + P_CORRUPT:
                self.fault[k] = 2
            elif u[k] < P_DROP + P_CORRUPT + P_TRUNCATE:
                self.fault[k] = 3
            k += 1
        self.fault[:5] = 0                     # the run begins with good frames: frame k at t_s = k / 1000
        self.garbage = {int(k): bytes(rng.choice(np.r_[0:0xFE, 0xFF], int(rng.integers(5, 61))).astype(np.uint8))
                        for k in np.flatnonzero(rng.random(n) < P_GARBAGE)}
        self.cut = {int(k): int(rng.integers(5, 36)) for k in np.flatnonzero(self.fault == 3)}
        # stalls at 1.5..4 s intervals in [1 s, duration - 4 s]: (start s, length s, kind)
        self.stalls, t = [], 1.0
        while True:
            t += float(rng.uniform(1.5, 4.0))
            length = math.exp(rng.uniform(math.log(STALL_MIN_S), math.log(STALL_MAX_S)))
            if t + length > duration_s - 4.0:
                break
            self.stalls.append((t, length, ("sender", "host", "both")[int(rng.integers(0, 3))]))
            t += length

    def wire(self, k: int) -> bytes:
        f = self.fault[k] if k < len(self.fault) else 0
        g = self.garbage.get(k, b"")
        if f == 1:
            return g
        b = frame(k)
        if f == 2:
            b = b[:10] + bytes([b[10] ^ 0x5A]) + b[11:]
        elif f == 3:
            b = b[:self.cut[k]]
        return g + b


class Device(threading.Thread):
    """Sends frame k at t0 + k / RATE_HZ (in 2 ms batches); during a sender stall it holds
    its frames and sends them late in one burst; a full pty (the monitor is not reading)
    holds them back too. Nothing the device produced is ever discarded."""

    def __init__(self, master: int, plan: Plan, n_send: int) -> None:
        super().__init__(name="fake-kvh", daemon=True)
        self.master, self.plan, self.n_send = master, plan, n_send
        self.stop = threading.Event()
        self.hold_until = 0.0
        self.t0 = None
        self.k = 0                       # frames produced so far
        self.preamble = threading.Event()

    def run(self) -> None:
        out = bytearray()
        while not self.preamble.is_set() and not self.stop.is_set():   # idle line noise before the frames
            self._write(bytearray(b"\x00" * 16))
            time.sleep(0.02)
        self.t0 = time.monotonic()
        while not self.stop.is_set() and (self.k < self.n_send or out):
            now = time.monotonic()
            due = min(self.n_send, int((now - self.t0) * RATE_HZ))
            if due > self.k:
                out += b"".join(self.plan.wire(k) for k in range(self.k, due))
                self.k = due
            if now >= self.hold_until and out:
                self._write(out)
            time.sleep(0.002)

    def _write(self, out: bytearray) -> None:
        try:
            n = os.write(self.master, out)
        except BlockingIOError:
            return
        except OSError:             # the monitor closed the port at its end
            self.stop.set()
            return
        del out[:n]


def hog() -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def summary_counters(out: str) -> tuple[dict[str, int], int]:
    counters, n_samples = {}, 0
    m = re.search(r"^\s*(\d+) samples at", out, re.M)
    if m:
        n_samples = int(m.group(1))
    part = out.split("Counters:", 1)
    for line in (part[1].splitlines() if len(part) > 1 else []):
        m = re.match(r"^\s+([\w.]+)\s+(-?\d+)\s*$", line)
        if m:
            counters[m.group(1)] = int(m.group(2))
        elif line.strip() and not line.startswith(" "):
            break
    return counters, n_samples


def event_totals(rrd: str) -> dict[str, int]:
    """Sums of the counts the .rrd's events carry: crc_error 'N frame(s) failed', gap
    'N sample(s) lost' and 'N more gaps, M samples lost'."""
    from helpers.rrd import read_event_messages
    tot = {"crc_errors": 0, "samples_missing": 0, "seq_gaps": 0}
    for x in read_event_messages(rrd, "/events"):
        if x.startswith("crc_error:"):
            tot["crc_errors"] += int(x.split()[1])
        elif x.startswith("gap:"):
            m = re.match(r"gap: (\d+) more gaps, (\d+) samples lost", x)
            if m:
                tot["seq_gaps"] += int(m.group(1))
                tot["samples_missing"] += int(m.group(2))
            else:
                tot["seq_gaps"] += 1
                tot["samples_missing"] += int(x.split()[1])
    return tot


def archive_in(parent: str) -> str:
    """The archive folder `fogmon monitor --archive PARENT` made in PARENT ("" before it exists)."""
    found = [e.path for e in os.scandir(parent) if e.name.startswith(FOLDER_PREFIX)]
    return found[0] if found else ""


def run_once(mode: str, args, workdir: str, connect_url: str | None) -> bool:
    rng = np.random.default_rng(args.seed)
    n = math.floor(args.duration_s * RATE_HZ - 0.5 + 1e-9) + 1   # samples of the --duration-s run
    plan = Plan(n + 5 * RATE_HZ, args.duration_s, rng)
    master, slave, tty = open_pty()
    runs = os.path.join(workdir, f"arch-{mode}")   # the monitor makes its archive folder in it
    os.makedirs(runs, exist_ok=True)
    window = min(8.192, 2 ** math.floor(math.log2(n / 4)) / RATE_HZ)
    cmd = [sys.executable, "-m", "fogmon", "monitor", "--serial", tty, "--protocol", "kvh-a", "--axis", "z",
           "--kvh-rot", "rate", "--kvh-units", "deg", "--duration-s", f"{args.duration_s:g}", "--archive", runs,
           "--window-s", f"{window:g}", "--hop-s", f"{window / 8:g}", "--no-progress"]
    rrd = None
    if mode == "rrd":
        rrd = os.path.join(workdir, "live.rrd")
        cmd += ["--rrd", rrd]
    elif mode == "connect":
        cmd += ["--connect", connect_url]
    dev = Device(master, plan, len(plan.fault))
    env = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
    mon = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    dev.start()
    stalls_done = []
    try:
        while not has_open(mon.pid, tty) and mon.poll() is None:
            time.sleep(0.01)
        # frames begin once the monitor decodes what it reads (pyserial flushes the port while opening it)
        while not os.path.exists(os.path.join(archive_in(runs), "raw-0001.bin")) and mon.poll() is None:
            time.sleep(0.01)
        dev.preamble.set()
        while dev.t0 is None:
            time.sleep(0.001)
        for start, length, kind in plan.stalls:
            while time.monotonic() < dev.t0 + start and mon.poll() is None:
                time.sleep(0.005)
            if mon.poll() is not None:
                break
            if kind in ("sender", "both"):
                dev.hold_until = time.monotonic() + length
            if kind in ("host", "both"):
                mon.send_signal(signal.SIGSTOP)
                time.sleep(length)
                mon.send_signal(signal.SIGCONT)
            stalls_done.append((length, kind))
        out, err = mon.communicate(timeout=args.duration_s * 3 + 60)
    finally:
        if mon.poll() is None:
            mon.send_signal(signal.SIGCONT)
            mon.kill()
            mon.wait()
        dev.stop.set()
        dev.join(5)
        os.close(master)
        os.close(slave)
    counters, n_samples = summary_counters(out)
    checks: list[tuple[str, bool]] = []
    checks.append((f"monitor exit code {mon.returncode}", mon.returncode == 0))
    if mon.returncode != 0:
        print(err.strip().splitlines()[-1] if err.strip() else "(no stderr)")
    # what was sent inside the run: frames 0 .. n_samples-1 on the monitor's grid
    fault = plan.fault[:n_samples]
    intact = np.flatnonzero(fault == 0)
    arch = archive_in(runs)
    logs = find_pieces(arch, "samples.csv")
    recs = [read_replay_log(p) for p in logs]
    t = np.concatenate([r.t_s for r in recs]) if recs else np.zeros(0)
    rate = np.concatenate([r.rate_dph for r in recs]) if recs else np.zeros(0)
    k_arch = np.rint(rate / (3600 * DPS_PER_K)).astype(np.int64)
    tb_err = int(np.max(np.abs(np.rint(t * RATE_HZ).astype(np.int64) - k_arch))) if len(t) else -1
    same = len(k_arch) == len(intact) and np.array_equal(k_arch, intact)
    lost_true = int(n_samples - len(intact))
    missing = counters.get("samples_missing", -1)
    phantom, missed = max(0, missing - lost_true), max(0, lost_true - missing)
    lost_tail = 0
    while n - 1 - lost_tail >= 0 and plan.fault[n - 1 - lost_tail] != 0:
        lost_tail += 1
    host = [x for x in stalls_done if x[1] != "sender"]
    print(f"  stalls: {len(stalls_done)} ({len(host)} of the monitor's host, longest "
          f"{max([x[0] for x in stalls_done], default=0):.2f} s, total {sum(x[0] for x in stalls_done):.2f} s)")
    print(f"  samples {n_samples} of {n} (the last {lost_tail} frame(s) before the cut lost)")
    print(f"  valid frames sent {len(intact)} / archived {len(k_arch)}  (same frames: {same})")
    print(f"  phantom gaps {phantom} samples, missed losses {missed} samples "
          f"(reported missing {missing}, truly lost {lost_true})")
    print(f"  time-base error {tb_err} samples")
    checks += [("samples = the --duration-s run", n_samples == n - lost_tail),
               ("valid frames sent == archived", same), ("phantom gaps == 0", phantom == 0),
               ("missed losses == 0", missed == 0), ("time-base error == 0", tb_err == 0)]
    want_crc = int(np.count_nonzero(fault >= 2))
    crc = counters.get("crc_errors", -1)
    print(f"  crc_errors {crc} (frames corrupted or truncated: {want_crc}), frames_ok {counters.get('frames_ok')} "
          f"(intact: {len(intact)}), rows archived {len(k_arch)}")
    checks += [("crc_errors == corrupted + truncated frames", crc == want_crc),
               ("frames_ok == archived rows", counters.get("frames_ok") == len(k_arch))]
    # the raw capture decoded again: the same samples and counters
    raws = find_pieces(arch, "raw.bin")
    breaks = []
    for p in raws:
        with open(p + ".json", encoding="utf-8") as fh:
            breaks += json.load(fh).get("breaks", [])
    print(f"  outages in the raw capture's sidecar: {len(breaks)} (the port was never reopened)")
    checks.append(("no outage in the sidecar", not breaks))
    try:
        rep = open_raw_capture(raws)
        blocks = list(rep.blocks())
    except FogmonError as e:
        print(f"  raw capture cannot be replayed: {e}")
        rep, blocks = None, []
    vt = np.concatenate([b.t_s[b.valid] for b in blocks]) if blocks else np.zeros(0)
    vr = np.concatenate([b.rate_dph[b.valid] for b in blocks]) if blocks else np.zeros(0)
    rep_same = len(vt) == len(t) and np.allclose(vt, t, rtol=0, atol=1e-9) and \
        np.allclose(vr, rate, rtol=1e-11, atol=0)      # the archive keeps 12 significant digits
    keys = ("frames_ok", "crc_errors", "bytes_skipped", "seq_gaps", "samples_missing", "invalid_samples")
    rc = rep.counters if rep is not None else {}
    diff = {k: (counters.get(k), rc.get(k)) for k in keys if counters.get(k) != rc.get(k)}
    n_rep = sum(len(b) for b in blocks)
    print(f"  raw capture replayed: {n_rep} samples, {len(vt)} valid, same as samples.csv: {rep_same}; "
          f"counters that differ from the live run: {diff or 'none'}")
    checks += [("raw capture replay == samples.csv", rep_same and n_rep == n_samples),
               ("raw capture counters == live counters", not diff)]
    if rrd:
        ev = event_totals(rrd.replace(".rrd", "-0001.rrd"))
        evdiff = {k: (counters.get(k), v) for k, v in ev.items() if counters.get(k) != v}
        print(f"  events in the .rrd: {ev}; differing from the counters: {evdiff or 'none'}")
        checks.append(("counters == events", not evdiff))
    ok = all(c for _, c in checks)
    for name, c in checks:
        if not c:
            print(f"  FAILED: {name}")
    print(f"  {mode}: {'PASS' if ok else 'FAIL'}")
    return ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=60.0, help="length of each monitor run, s (default 60)")
    ap.add_argument("--seed", type=int, default=1, help="seed of the faults and stalls (default 1)")
    ap.add_argument("--hogs", type=int, default=2, help="CPU-bound processes running beside (default 2)")
    ap.add_argument("--modes", default="plain,rrd,connect", help="runs: plain, rrd, connect (default all)")
    args = ap.parse_args(argv)
    if args.duration_s < 10:
        ap.error("--duration-s must be >= 10 s (stalls need room)")
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    workdir = tempfile.mkdtemp(prefix="fogmon-live-under-load-")
    hogs = [hog() for _ in range(args.hogs)]
    server = None
    results = {}
    try:
        for mode in modes:
            url = None
            if mode == "connect":
                import socket

                from fogmon.sinks.rerun.server import start_grpc_server
                with socket.socket() as s:
                    s.bind(("127.0.0.1", 0))
                    port = s.getsockname()[1]
                server, url = start_grpc_server("127.0.0.1", port)
            print(f"{mode}: fogmon monitor {args.duration_s:g} s at {RATE_HZ} Hz, seed {args.seed}, "
                  f"{args.hogs} CPU hogs" + (f", --connect {url}" if url else "")
                  + (", --rrd" if mode == "rrd" else ""))
            results[mode] = run_once(mode, args, workdir, url)
            if server is not None:
                os.killpg(server.pid, signal.SIGKILL)
                server.wait()
                server = None
    finally:
        for h in hogs:
            h.kill()
            h.wait()
        if server is not None:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait()
        shutil.rmtree(workdir, ignore_errors=True)
    ok = all(results.values()) and len(results) == len(modes)
    verdicts = ", ".join(f"{m} {'PASS' if r else 'FAIL'}" for m, r in results.items())
    print(f"live_under_load: {'PASS' if ok else 'FAIL'} ({verdicts})")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
