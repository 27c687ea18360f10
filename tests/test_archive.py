"""Archive: replay log + raw capture, flushed in whole lines at least every flush_s; the
monitor killed with SIGKILL leaves an archive that replays and is short by <= 1 s;
--duration-s stops the monitor by itself."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.recording import read_replay_log
from fogmon.sinks.archive import Archive
from fogmon.sources.replay import open_raw_capture
from sources_fake_device import FakeKvh, has_open

FS = 200.0


class FakeSource:
    name, rate_hz, counters = "fake gyro", 10.0, {}


def block(k0, n, valid=None):
    t = (k0 + np.arange(n)) / 10.0
    return Block.make(t, t * 100, valid, {"temp_c": np.full(n, 21.5)})


def test_archive_writes_valid_samples_and_flushes_by_time(tmp_path):
    now = [0.0]
    a = Archive(str(tmp_path / "a"), FakeSource(), flush_s=0.5, clock=lambda: now[0], background_flush=False)
    a.write(block(0, 5, valid=[1, 1, 0, 1, 1]))
    assert os.path.getsize(a.replay_log_path) == 0          # buffered
    now[0] = 0.6
    a.write(block(5, 3))
    text = open(a.replay_log_path).read()
    assert text.endswith("\n") and text.count("\n") == 5 + 7      # magic, 3 metadata, header + 7 rows
    rec = read_replay_log(a.replay_log_path)
    np.testing.assert_allclose(rec.t_s, [0, 0.1, 0.3, 0.4, 0.5, 0.6, 0.7])   # the invalid sample is a gap
    assert rec.meta["sample_rate_hz"] == "10" and rec.meta["sensor"] == "fake gyro"
    a.close()
    assert a.counters["rows_written"] == 7


def test_archive_flushes_in_the_background_when_no_data_flows(tmp_path):
    a = Archive(str(tmp_path / "a"), FakeSource(), flush_s=0.05)
    a.write(block(0, 3))
    t_end = time.monotonic() + 5
    while os.path.getsize(a.replay_log_path) == 0 and time.monotonic() < t_end:
        time.sleep(0.01)
    assert len(read_replay_log(a.replay_log_path)) == 3
    a.close()


def test_archive_refuses_to_overwrite(tmp_path):
    Archive(str(tmp_path / "a"), FakeSource()).close()
    with pytest.raises(FogmonError, match="already holds an archive"):
        Archive(str(tmp_path / "a"), FakeSource())


def monitor(link, archive, *extra):
    return subprocess.Popen([sys.executable, "-m", "fogmon", "monitor", "--serial", link, "--protocol", "kvh-a",
                             "--kvh-rot", "rate", "--kvh-units", "deg", "--rate-hz", str(FS), "--archive", archive,
                             "--no-progress", "--quiet", *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def run_device(dev, proc, until, t0=None, k=0):
    """Send at FS (once the monitor has the port open and flushed) until ``until()``;
    returns (t0, next k) to carry on."""
    if t0 is None:
        t_end = time.monotonic() + 60
        while not has_open(proc.pid, dev.tty) and time.monotonic() < t_end:
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.01)
        time.sleep(0.3)
        t0 = time.monotonic()
    while not until() and time.monotonic() - t0 < 60:
        try:
            k = dev.send_due(t0, k)
        except TimeoutError:        # the monitor stopped reading (it is finishing or gone)
            break
        time.sleep(0.01)
    return t0, k


def test_sigkill_loses_at_most_one_second(tmp_path):
    dev = FakeKvh(str(tmp_path), FS)
    arch = str(tmp_path / "arch")
    proc = monitor(dev.link, arch)
    try:
        csv = os.path.join(arch, "samples.csv")
        # warm up until the first rows are on disk (imports and JIT compilation done), then 2 s more
        t0, k = run_device(dev, proc, until=lambda: os.path.exists(csv) and os.path.getsize(csv) > 200)
        t_kill = time.monotonic() + 2.0
        run_device(dev, proc, until=lambda: time.monotonic() >= t_kill, t0=t0, k=k)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
        dev.close()
    sent = dev.sent
    rec = read_replay_log(csv)                                   # no half-written row
    ks = list(np.rint(rec.rate_dph / 3600).astype(int))
    assert ks == sent[:len(ks)] and len(sent) - len(ks) <= FS     # a prefix, short by <= 1 s
    cap = open_raw_capture(os.path.join(arch, "raw.bin"))
    v = np.concatenate([b.rate_dph[b.valid] for b in cap.blocks()])
    kc = list(np.rint(v / 3600).astype(int))
    assert kc == sent[:len(kc)] and len(sent) - len(kc) <= FS
    print(f"SIGKILL: {len(sent)} frames sent, replay log short by {len(sent) - len(ks)}, "
          f"raw capture short by {len(sent) - len(kc)} samples at {FS:g} Hz")


def test_monitor_duration_stops_by_itself(tmp_path):
    dev = FakeKvh(str(tmp_path), FS)
    arch = str(tmp_path / "arch")
    proc = monitor(dev.link, arch, "--duration-s", "1")
    try:
        run_device(dev, proc, until=lambda: proc.poll() is not None)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        dev.close()
    assert proc.returncode == 0, err
    rec = read_replay_log(os.path.join(arch, "samples.csv"))
    assert len(rec) == int(FS)                                   # 1 s of recording time
    assert list(np.rint(rec.rate_dph / 3600).astype(int)) == dev.sent[:len(rec)]


def test_valid_samples_without_aux_are_counted_not_written(tmp_path):
    a = Archive(str(tmp_path / "a"), FakeSource())
    b = block(0, 4)
    b.aux["temp_c"][:2] = np.nan         # e.g. KVH format C before its first temperature frame
    a.write(b)
    a.close()
    assert a.counters == {"rows_written": 2, "rows_without_aux": 2, "raw_bytes": 0, "raw_frames": 0}
    np.testing.assert_allclose(read_replay_log(a.replay_log_path).t_s, [0.2, 0.3])


def test_monitor_unplug_replug_archives_every_sample_sent_while_connected(tmp_path):
    dev = FakeKvh(str(tmp_path), FS)
    arch = str(tmp_path / "arch")
    raw = os.path.join(arch, "raw.bin")
    proc = monitor(dev.link, arch)

    def received_all():        # the archive's raw capture (flushed <= 0.5 s) holds every byte sent
        return os.path.exists(raw) and os.path.getsize(raw) == 36 * len(dev.sent)

    def wait(cond, what):
        t_end = time.monotonic() + 30
        while not cond():
            assert proc.poll() is None and time.monotonic() < t_end, (what, proc.communicate() if proc.poll() else "")
            time.sleep(0.01)

    try:
        t_stop = [None]
        t0, k = run_device(dev, proc, until=lambda: len(dev.sent) >= 160)
        wait(received_all, "bytes before the unplug")
        old = dev.tty
        dev.unplug()
        wait(lambda: not has_open(proc.pid, old), "monitor notices the unplug")
        time.sleep(0.5)
        dev.plug()
        wait(lambda: has_open(proc.pid, dev.tty), "monitor reopens")
        time.sleep(0.3)                                      # open + input flush done
        k = int((time.monotonic() - t0) * FS)                # the gyro kept counting meanwhile
        t_stop[0] = time.monotonic() + 1.0
        run_device(dev, proc, until=lambda: time.monotonic() > t_stop[0], t0=t0, k=k)
        wait(received_all, "bytes after the replug")
        proc.send_signal(signal.SIGINT)                      # Ctrl-C: clean stop
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        dev.close()
    assert proc.returncode == 0
    rec = read_replay_log(os.path.join(arch, "samples.csv"))
    ks = list(np.rint(rec.rate_dph / 3600).astype(int))
    assert ks == dev.sent
    np.testing.assert_array_equal(np.rint(rec.t_s * FS).astype(int), np.array(ks) - ks[0])   # gap kept, right length
