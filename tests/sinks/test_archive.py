"""Archive: replay log + raw capture, flushed in whole lines at least every flush_s; the
monitor killed with SIGKILL leaves an archive that replays and is short by <= 1 s;
--duration-s stops the monitor by itself; SIGTERM and SIGHUP stop it cleanly; --rotate-s
splits it into pieces that replay alone and, as one, without a seam; nothing received
leaves nothing behind."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from helpers.doubles import archive_in
from helpers.fake_device import MAX_RATE_DPH, FakeKvh, frame_k, has_open, stream

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.formats.archive import LOCK
from fogmon.formats.replay_log import read_replay_log
from fogmon.sinks.archive import Archive
from fogmon.sources.files.capture import open_raw_capture

FS = 200.0
#: A safety bound (s) on waiting for the monitor: it synchronises on data (the port open,
#: rows on disk), and a cold start (imports, numba compiling in a fresh venv) on a loaded
#: 2-core machine has taken over 60 s; a monitor that has done nothing after this is broken.
WAIT_S = 600.0
#: the tests that start a monitor wait up to WAIT_S, beyond the suite's 300 s per test
pytestmark = pytest.mark.timeout(2 * WAIT_S)


class FakeSource:
    name, sample_rate_hz, counters, axes = "fake gyro", 10.0, {}, ()


def block(k0, n, valid=None):
    t = (k0 + np.arange(n)) / 10.0
    return Block.make(t, t * 100, valid, {"temp_c": np.full(n, 21.5)})


def test_archive_writes_valid_samples_and_flushes_by_time(tmp_path):
    now = [0.0]
    a = Archive(str(tmp_path / "a"), FakeSource(), flush_s=0.5, clock=lambda: now[0], background_flush=False)
    assert os.listdir(a.directory) == [LOCK]          # files come with their first data (the lock: its writer)
    a.write(block(0, 5, valid=[1, 1, 0, 1, 1]))
    assert a.replay_log_path.endswith("samples-0001.csv") and os.path.getsize(a.replay_log_path) == 0  # buffered
    now[0] = 0.6
    a.write(block(5, 3))
    with open(a.replay_log_path) as f:
        text = f.read()
    assert text.endswith("\n") and text.count("\n") == 6 + 7      # magic, 4 metadata, header + 7 rows
    rec = read_replay_log(a.replay_log_path)
    np.testing.assert_allclose(rec.t_s, [0, 0.1, 0.3, 0.4, 0.5, 0.6, 0.7])   # the invalid sample is a gap
    assert rec.meta["sample_rate_hz"] == "10" and rec.meta["sensor"] == "fake gyro" and rec.meta["piece"] == "1"
    a.close()
    assert a.counters["rows_written"] == 7


def test_archive_flushes_in_the_background_when_no_data_flows(tmp_path):
    a = Archive(str(tmp_path / "a"), FakeSource(), flush_s=0.05)
    a.write(block(0, 3))
    t_end = time.monotonic() + WAIT_S  # a guard against a hang, not a timing
    while os.path.getsize(a.replay_log_path) == 0 and time.monotonic() < t_end:
        time.sleep(0.01)
    assert len(read_replay_log(a.replay_log_path)) == 3
    a.close()


def test_archive_refuses_to_overwrite(tmp_path):
    with Archive(str(tmp_path / "a"), FakeSource()) as a:
        a.write(block(0, 3))
    with pytest.raises(FogmonError, match=r"already holds an archive \(samples-0001.csv\)"):
        Archive(str(tmp_path / "a"), FakeSource())


def test_archive_that_received_nothing_leaves_no_folder(tmp_path):
    Archive(str(tmp_path / "new"), FakeSource()).close()
    Archive(str(tmp_path), FakeSource()).close()                  # a folder it did not create stays
    assert list(tmp_path.iterdir()) == []


def monitor(link, archive, *extra, quiet=True):
    """`fogmon monitor` of the fake KVH at ``link``, archiving into a new folder in
    ``archive`` (made here; archive_in finds it)."""
    os.makedirs(archive, exist_ok=True)
    return subprocess.Popen([sys.executable, "-m", "fogmon", "monitor", "--serial", link, "--protocol", "kvh-a",
                             "--axis", "z", "--kvh-rot", "rate", "--kvh-units", "deg", "--rate-hz", str(FS),
                             "--archive", archive, "--max-rate-dph", str(MAX_RATE_DPH),
                             "--no-progress", *(["--quiet"] if quiet else []), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def run_device(dev, proc, until, t0=None, k=0):
    """Send at FS (once the monitor has the port open and flushed) until ``until()``;
    returns (t0, next k) to carry on."""
    if t0 is None:
        t_end = time.monotonic() + WAIT_S
        while not has_open(proc.pid, dev.tty) and time.monotonic() < t_end:
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.01)
        t0 = time.monotonic()       # frames sent before pyserial's open() flushed its input are lost:
                                    # the checks start at the first frame archived (``listened``)
    while not until() and time.monotonic() - t0 < WAIT_S:
        try:
            k = dev.send_due(t0, k)
        except TimeoutError:        # the monitor stopped reading (it is finishing or gone)
            break
        time.sleep(0.01)
    return t0, k


def listened(sent, ks):
    """The frames sent from the first one the monitor archived on: pyserial's open()
    flushes the port's input, so what the device sent before that was never received
    (a few frames, or seconds' worth on a loaded host; the test cannot know when the
    flush happens). Every frame after the first one archived is checked."""
    assert ks, "nothing archived"
    i0 = sent.index(ks[0])
    assert i0 <= 10 * FS, f"{i0} frames sent before the monitor listened"    # a loaded host: seconds
    return sent[i0:]


def test_sigkill_loses_at_most_one_second(tmp_path):
    dev = FakeKvh(str(tmp_path), FS)
    runs = str(tmp_path / "runs")
    proc = monitor(dev.link, runs)
    try:
        def csv():
            return os.path.join(archive_in(runs), "samples-0001.csv")
        # warm up until the first rows are on disk (imports and JIT compilation done), then 2 s more
        t0, k = run_device(dev, proc, until=lambda: os.path.exists(csv()) and os.path.getsize(csv()) > 200)
        t_kill = time.monotonic() + 2.0
        run_device(dev, proc, until=lambda: time.monotonic() >= t_kill, t0=t0, k=k)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
        dev.close()
    arch = archive_in(runs)
    rec = read_replay_log(csv())                                 # no half-written row
    ks = list(np.rint(rec.rate_dph / 3600).astype(int))
    sent = listened(dev.sent, ks)
    assert ks == sent[:len(ks)] and len(sent) - len(ks) <= FS     # a prefix, short by <= 1 s
    cap = open_raw_capture(os.path.join(arch, "raw-0001.bin"))
    v = np.concatenate([b.rate_dph[b.valid] for b in cap.blocks()])
    kc = list(np.rint(v / 3600).astype(int))
    assert kc == sent[:len(kc)] and len(sent) - len(kc) <= FS
    print(f"SIGKILL: {len(sent)} frames sent, replay log short by {len(sent) - len(ks)}, "
          f"raw capture short by {len(sent) - len(kc)} samples at {FS:g} Hz")


def test_monitor_duration_stops_by_itself(tmp_path):
    dev = FakeKvh(str(tmp_path), FS)
    runs = str(tmp_path / "runs")
    proc = monitor(dev.link, runs, "--duration-s", "1")
    try:
        run_device(dev, proc, until=lambda: proc.poll() is not None)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        dev.close()
    assert proc.returncode == 0, err
    rec = read_replay_log(os.path.join(archive_in(runs), "samples-0001.csv"))
    assert len(rec) == int(FS)                                   # 1 s of recording time
    ks = list(np.rint(rec.rate_dph / 3600).astype(int))
    assert ks == listened(dev.sent, ks)[:len(rec)]


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
    runs = str(tmp_path / "runs")
    proc = monitor(dev.link, runs)

    def received_all():        # the archive's raw capture (flushed <= 0.5 s) ends with the last frame sent
        raw = os.path.join(archive_in(runs), "raw-0001.bin")
        if not os.path.exists(raw):
            return False
        with open(raw, "rb") as fh:
            fh.seek(max(0, os.path.getsize(raw) - 36))
            return fh.read() == frame_k(dev.sent[-1])

    def wait(cond, what):
        t_end = time.monotonic() + 300  # a guard against a hang (a cold compile under load), not a timing
        while not cond():
            assert proc.poll() is None and time.monotonic() < t_end, (what, proc.communicate() if proc.poll() else "")
            time.sleep(0.01)

    try:
        t_stop = [None]
        t0, k = run_device(dev, proc, until=lambda: len(dev.sent) >= 160)
        wait(received_all, "bytes before the unplug")
        old, n_before = dev.tty, len(dev.sent)
        dev.unplug()
        wait(lambda: not has_open(proc.pid, old), "monitor notices the unplug")
        time.sleep(0.5)
        dev.plug()
        wait(lambda: has_open(proc.pid, dev.tty), "monitor reopens")
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
    rec = read_replay_log(os.path.join(archive_in(runs), "samples-0001.csv"))
    ks = list(np.rint(rec.rate_dph / 3600).astype(int))
    n1 = sum(k <= dev.sent[n_before - 1] for k in ks)    # archived before the unplug
    assert ks == listened(dev.sent[:n_before], ks[:n1]) + listened(dev.sent[n_before:], ks[n1:])
    np.testing.assert_array_equal(np.rint(rec.t_s * FS).astype(int), np.array(ks) - ks[0])   # gap kept, right length


class PacedPort:
    """A serial port (pyserial's ``read``/``in_waiting``/``close``) that sends ``data``
    in reads of ``chunk`` bytes (splitting frames) and never more than ``lead`` frames
    ahead of what the pipeline has archived (``consumed()`` samples): a device paced by
    the data, not by the clock. Its ``clock`` advances with the bytes read at the
    device's pace (bytes / frame length / rate), so the source's timing follows the
    data, not the load of the machine."""

    def __init__(self, data: bytes, chunk: int, sample_rate_hz: float, lead: int, consumed, frame_len: int = 36):
        self.data, self.chunk, self.lead, self.consumed = data, chunk, lead, consumed
        self.frame_len, self.pos, self.now_s = frame_len, 0, 0.0
        self._s_per_byte = 1.0 / (frame_len * sample_rate_hz)

    def _allowed(self):
        return min(len(self.data), (self.consumed() + self.lead) * self.frame_len) - self.pos

    @property
    def in_waiting(self):
        return max(0, min(self.chunk, self._allowed()))

    def read(self, n):
        out = self.data[self.pos:self.pos + max(0, min(n, self.chunk, self._allowed()))]
        if not out:
            time.sleep(0.001)
        self.pos += len(out)
        self.now_s += len(out) * self._s_per_byte
        return out

    def clock(self):
        return self.now_s

    def close(self):
        pass


def test_rotation_pieces_replay_alone_and_as_one_without_seams(tmp_path, monkeypatch):
    """--rotate-s 1 at 200 Hz over 4.5 s: five pieces of samples and raw bytes. Frame 200
    (first of piece 2) fails its CRC and frame 400 (first of piece 3) is lost, so pieces
    2 and 3 start with a missing sample; garbage sits inside piece 1."""
    from helpers.doubles import args_for

    from fogmon.pipeline import PipelineConfig as _args, run_pipeline
    from fogmon.sources.codecs.protocols import make_codec
    from fogmon.sources.devices.serial_port import SerialSource
    from fogmon.sources.files.capture import RawCaptureSource
    from fogmon.sources.files.replay_log import ReplayLogSet
    from fogmon.sources.open import open_replay_source

    data, _ = stream(1200, {150: "garbage", 200: "corrupt", 400: "drop"})
    arch, lead = tmp_path / "arch", 25     # (a wake of the reader takes all the device allows: up to `lead` frames)
    port = PacedPort(data, 50, FS, lead, consumed=lambda: archive.counters["rows_written"])
    src = SerialSource("fake", 921600, make_codec("kvh-a", axis="z", kvh_rot="rate", kvh_units="deg", sample_rate_hz=FS,
                                                                   max_rate_dph=MAX_RATE_DPH),
                       opener=lambda: port, clock=port.clock, read_pause_s=0)   # paced by the data
    archive = Archive(str(arch), src)
    # the port is paced by the pipeline, not by the clock: no wall-clock stop (a loaded host
    # would otherwise end the run before its 4.5 s of recording)
    monkeypatch.setattr("fogmon.pipeline.run.LIVE_WALL_SLACK_S", 1e6)
    run_pipeline(src, _args(window_s=0.64, rotate_s=1.0, duration_s=4.5), sinks=[archive])
    n = int(4.5 * FS)
    want = [k for k in range(n) if k not in (200, 400)]
    names = sorted(os.listdir(arch))
    assert [x for x in names if x.endswith(".csv")] == [f"samples-000{k}.csv" for k in range(1, 6)]
    # each replay-log piece alone: a complete log of its second, in order
    got = []
    for k in range(1, 6):
        rec = read_replay_log(arch / f"samples-000{k}.csv")
        assert rec.meta["piece"] == str(k) and rec.meta["sample_rate_hz"] == "200"
        assert k - 1 <= rec.t_s[0] and rec.t_s[-1] < k
        got += list(np.rint(rec.rate_dph / 3600).astype(int))
    assert got == want
    # each raw piece alone: its sidecar, a frame boundary at its start, a run of whole frames
    raws = [x for x in names if x.endswith(".bin")]
    assert raws == [f"raw-000{k}.bin" for k in range(1, len(raws) + 1)] and len(raws) >= 5
    joined = b"".join((arch / x).read_bytes() for x in raws)
    assert joined == data[:len(joined)] and len(joined) < 36 * (n + 1)   # the bytes received, up to the cut
    for j, x in enumerate(raws):
        piece = open_raw_capture(str(arch / x))
        ks = np.rint(np.concatenate([b.rate_dph[b.valid] for b in piece.blocks()]) / 3600).astype(int)
        assert j == 0 or (arch / x).read_bytes()[:4] == bytes.fromhex("fe81ff55")     # a whole frame first
        # after the samples' seam, by the pipeline's lag: the device is up to `lead` frames ahead of the
        # archive, and the cut comes at the end of the next wake's read, up to `lead` frames more
        assert j * FS <= ks[0] <= j * FS + 2 * lead + 2
        assert set(range(ks[0], ks[-1] + 1)) - set(ks) <= {200, 400}    # consecutive but for the lost frames
    # the folder as one recording: the sample grid runs on across every seam
    for argv in ((), ("--kvh-rot", "rate")):          # decoder options: decode the raw pieces again
        whole = open_replay_source(str(arch), args_for(*argv))
        assert isinstance(whole, RawCaptureSource if argv else ReplayLogSet)
        blocks = list(whole.blocks())
        t = np.concatenate([b.t_s for b in blocks])       # raw and samples end at the --duration-s cut
        valid = np.concatenate([b.valid for b in blocks])
        rate = np.concatenate([b.rate_dph for b in blocks])
        np.testing.assert_allclose(t, np.arange(n) / FS, atol=1e-9)
        assert list(np.flatnonzero(~valid)) == [200, 400]
        assert list(np.rint(rate[valid] / 3600).astype(int)) == want
        if not argv:
            assert whole.n_samples == n and whole.counters["samples_missing"] == 2
            assert [e.kind for b in blocks for e in b.events] == ["gap", "gap"]


def run_to_rows(proc, dev, csv, rows):
    """Feed the monitor until ``csv()`` holds ``rows`` rows (synchronise on its output)."""
    def enough():
        return os.path.exists(csv()) and open(csv()).read().count("\n") >= rows + 5
    return run_device(dev, proc, until=enough)


@pytest.mark.filterwarnings("error:RRD file has no footer")
@pytest.mark.parametrize("sig, name", [(signal.SIGTERM, "SIGTERM"), (signal.SIGHUP, "SIGHUP")])
def test_sigterm_and_sighup_stop_the_monitor_cleanly(tmp_path, sig, name):
    from rerun.chunk import RrdReader

    dev = FakeKvh(str(tmp_path), FS)
    runs, rrd = str(tmp_path / "runs"), str(tmp_path / "live.rrd")
    proc = monitor(dev.link, runs, "--rrd", rrd, quiet=False)
    proc_out = ("", "")
    try:
        def csv():
            return os.path.join(archive_in(runs), "samples-0001.csv")
        t0, k = run_to_rows(proc, dev, csv, 300)
        proc.send_signal(sig)
        run_device(dev, proc, until=lambda: proc.poll() is not None, t0=t0, k=k)
        proc_out = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
        dev.close()
    out, err = proc_out
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert f"fogmon: interrupted ({name})" in out and "Overall Allan deviation" in out
    line = next(line for line in out.splitlines() if f"samples at {FS:g} Hz" in line)
    n, lost = int(line.split()[0]), int(line.split("(")[1].split()[0])
    rec = read_replay_log(csv())                              # flushed to the last sample processed
    ks = list(np.rint(rec.rate_dph / 3600).astype(int))
    assert len(rec) == n - lost and ks == listened(dev.sent, ks)[:len(ks)]
    assert not os.path.exists(os.path.join(tmp_path, "live-0001.rrd"))   # --rrd X writes X (pieces: --rotate-s)
    assert sum(1 for _ in RrdReader(rrd).stream()) > 0        # complete: a footer (else the warning fails)


def test_monitor_that_received_nothing_leaves_no_archive_or_rrd(tmp_path):
    dev = FakeKvh(str(tmp_path), FS)                          # plugged in, never sends
    runs, rrd = tmp_path / "runs", tmp_path / "x.rrd"
    proc = monitor(dev.link, str(runs), "--rrd", str(rrd), "--duration-s", "0.5")
    try:
        proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
        dev.close()
    assert sorted(os.listdir(tmp_path)) == ["runs"] and not os.listdir(runs)


def test_can_capture_pieces_replay_as_one_frame_stream(tmp_path):
    """CAN frames 0..299 at 100 Hz cut into pieces after frames 99 and 194; frames 195..219
    (0.25 s, more than a 4-bit counter wrap) never arrived: the joined pieces give the
    real gap, measured by the logs' absolute timestamps, and no gap at the other seam."""
    from helpers.can_gyro import DBC, gyro_msgs
    from helpers.doubles import args_for

    from fogmon.sources.codecs.can import load_dbc
    from fogmon.sources.devices.can_bus import CanSource
    from fogmon.sources.open import open_replay_source

    sample_rate_hz = 100.0
    src = CanSource("x", "virtual", load_dbc(DBC), dbc_path=DBC)      # never opened: the test plays the bus
    arch = tmp_path / "arch"
    with Archive(str(arch), src) as archive:
        for m in gyro_msgs(range(300), extra=False):
            k = round((m.timestamp - 1_000_000.0) * sample_rate_hz)
            if k in (100, 220):
                archive.rotate(2 if k == 100 else 3, k / sample_rate_hz)
            if not 195 <= k < 220:
                archive.frame(m)
    assert sorted(os.listdir(arch)) == ["frames-0001.asc", "frames-0001.asc.json", "frames-0002.asc",
                                        "frames-0002.asc.json", "frames-0003.asc", "frames-0003.asc.json",
                                        "gyro_example.dbc"]
    whole = open_replay_source(str(arch), args_for())
    blocks = list(whole.blocks())
    valid = np.concatenate([b.valid for b in blocks])
    rate = np.concatenate([b.rate_dph for b in blocks])
    assert len(valid) == 300 and list(np.flatnonzero(~valid)) == list(range(195, 220))
    np.testing.assert_allclose(rate[valid], 3.6 * np.r_[0:195, 220:300])
    assert whole.counters["samples_missing"] == 25
    for k, n in ((1, 100), (2, 95), (3, 80)):                          # and each piece alone
        piece = open_replay_source(str(arch / f"frames-000{k}.asc"), args_for())
        assert sum(int(b.valid.sum()) for b in piece.blocks()) == n
