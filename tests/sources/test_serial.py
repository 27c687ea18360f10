"""Serial source against fake KVH devices on loop://, on a pty and on a scripted port
(reads and clock jumps given by the test): exact accounting of corrupted, truncated,
dropped frames and garbage; the time base from the device (host stalls make no gap,
vanished or garbled bytes the exact gap); counters equal to events and archive at a
--duration-s cut; unplug and replug with the archive keeping every sample sent while
connected; replay of the raw capture gives the same samples."""
import json
import os
import threading
import time

import numpy as np
import pytest
import serial
from helpers.fake_device import MAX_RATE_DPH, FakeKvh, frame_k, open_pty, stream, write_all

from fogmon.errors import FogmonError
from fogmon.formats.replay_log import read_replay_log
from fogmon.pipeline import PipelineConfig, run_pipeline
from fogmon.sinks.archive import Archive
from fogmon.sinks.base import Sink
from fogmon.sources.codecs.kvh import KvhCodec
from fogmon.sources.codecs.lines import LinesCodec
from fogmon.sources.devices.serial_port import SerialSource
from fogmon.sources.files.capture import open_raw_capture

FS = 200.0
FAULTS = {5: "corrupt", 6: "drop", 7: "drop", 40: "truncate", 41: "garbage", 90: "corrupt", 91: "corrupt",
          130: "drop", 200: "garbage"}


def collect(src: SerialSource, n_expected: int, timeout_s: float = 10.0):
    blocks, t_end = [], time.monotonic() + timeout_s
    for b in src.blocks():
        blocks.append(b)
        if sum(len(x) for x in blocks) >= n_expected or time.monotonic() > t_end:
            break
    src.close()
    t = np.concatenate([b.t_s for b in blocks])
    return blocks, t, np.concatenate([b.rate_dph for b in blocks]), np.concatenate([b.valid for b in blocks])


def check_exact(src, t, rate, valid, intact):
    ks = np.rint(rate[valid] / 3600).astype(int)
    assert list(ks) == intact                                  # samples delivered = intact frames
    assert np.array_equal(np.rint(t[valid] * FS).astype(int), ks)   # each on its own grid slot
    assert (~valid).sum() == 256 - len(intact)                 # every lost frame flagged
    c = src.counters
    assert c["frames_ok"] == len(intact)
    assert c["crc_errors"] == 4 and c["bytes_skipped"] == 3 * 36 + 20 + 2 * 13
    assert c["seq_gaps"] == 4 and c["samples_missing"] == 256 - len(intact)
    assert c["invalid_samples"] == 0


def test_loop_url_exact_accounting():
    data, intact = stream(256, FAULTS)
    port = serial.serial_for_url("loop://", timeout=0.05)
    src = SerialSource("loop://", 921600, KvhCodec("a", "rate", "deg", "z", FS), opener=lambda: port)
    th = threading.Thread(target=port.write, args=(data,))   # loop:// holds 4096 bytes: write while reading
    th.start()
    blocks, t, rate, valid = collect(src, 256)
    th.join()
    check_exact(src, t, rate, valid, intact)
    crc = [e for b in blocks for e in b.events if e.kind == "crc_error"]
    assert 1 <= len(crc) <= 4 and sum(int(e.message.split()[0]) for e in crc) == 4


def test_pty_fake_device_exact_accounting():
    data, intact = stream(256, FAULTS)
    master, slave, path = open_pty()
    src = SerialSource(path, 921600, KvhCodec("a", "rate", "deg", "z", FS))

    def device():
        while src._thread is None:         # the reader runs once the port is open and flushed
            time.sleep(0.005)
        time.sleep(0.05)
        for i in range(0, len(data), 70):      # ~200 frames/s, frames split across writes
            write_all(master, data[i:i + 70])
            time.sleep(0.01)

    th = threading.Thread(target=device)
    th.start()
    try:
        _, t, rate, valid = collect(src, 256)
    finally:
        th.join()
        os.close(master)
        os.close(slave)
    check_exact(src, t, rate, valid, intact)


def test_cannot_open_is_one_line_error(tmp_path):
    from fogmon.errors import FogmonError
    src = SerialSource(str(tmp_path / "nope"), 9600, KvhCodec())
    with pytest.raises(FogmonError, match="cannot open"):
        next(src.blocks())


def test_unplug_replug_archive_keeps_every_sample_sent_while_connected(tmp_path):
    dev = FakeKvh(str(tmp_path), FS)
    src = SerialSource(dev.link, 921600, KvhCodec("a", "rate", "deg", "z", FS, MAX_RATE_DPH), backoff_s=(0.02, 0.2))
    archive = Archive(str(tmp_path / "archive"), src)

    def wait_open(reconnects):   # pyserial flushes input while opening: "connected" starts after that
        while src._thread is None or src.counters["reconnects"] < reconnects:
            time.sleep(0.005)
        time.sleep(0.05)

    def device():
        wait_open(0)
        t0 = time.monotonic()
        k = 0
        while time.monotonic() - t0 < 0.8:
            k = dev.send_due(t0, k)
            time.sleep(0.01)
        t_end = time.monotonic() + 5       # pull the cable once the bytes on the wire have arrived
        while src.counters["frames_ok"] < len(dev.sent) and time.monotonic() < t_end:
            time.sleep(0.005)
        dev.unplug()
        time.sleep(0.7)                          # > half a counter wrap (0.32 s): only the clock can tell
        dev.plug()
        wait_open(1)
        k = max(k, int((time.monotonic() - t0) * FS))      # the gyro kept counting while unplugged
        while time.monotonic() - t0 < 2.6:
            k = dev.send_due(t0, k)
            time.sleep(0.01)
        t_end = time.monotonic() + 30      # stop once every frame sent has been decoded
        while src.counters["frames_ok"] < len(dev.sent) and time.monotonic() < t_end:
            time.sleep(0.005)
        src.close()                        # the pipeline still delivers what was decoded

    th = threading.Thread(target=device)
    th.start()
    events = []

    class Events(Sink):
        def events(self, ev):
            events.extend(ev)

    summary = run_pipeline(src, PipelineConfig(window_s=0.64, keep_motion=True), [archive, Events()])
    counters = {**summary.counters, **archive.counters}
    th.join()
    dev.close()
    rec = read_replay_log(archive.replay_log_path)
    ks = np.rint(rec.rate_dph / 3600).astype(int)
    # every sample sent while connected
    assert list(ks) == dev.sent, (counters, [(e.t_s, e.kind, e.message) for e in events])
    k0 = dev.sent[0]
    assert np.array_equal(np.rint(rec.t_s * FS).astype(int), ks - k0)   # outage kept as a gap of the right length
    assert counters["disconnects"] == 1 and counters["reconnects"] == 1
    assert counters["samples_missing"] == dev.sent[-1] - k0 + 1 - len(dev.sent)
    kinds = [e.kind for e in events]
    assert kinds.count("disconnect") == 1 and kinds.count("reconnect") == 1 and "gap" in kinds
    # the raw capture decodes to exactly the same samples
    replay = open_raw_capture(archive.capture_path)
    rb = list(replay.blocks())
    t = np.concatenate([b.t_s for b in rb])
    v = np.concatenate([b.valid for b in rb])
    r = np.concatenate([b.rate_dph for b in rb])
    np.testing.assert_array_equal(t[v], rec.t_s)
    np.testing.assert_array_equal(r[v], rec.rate_dph)


# -- time base from the device; counters that agree ---------------------------------------
class ScriptedPort:
    """A serial port whose reader gets ``chunks[i]`` at its wake i, the clock jumping by
    ``stalls_s[i]`` (+ 1 ms) as that wake begins (the host did not read for that long;
    the OS kept the bytes): the source's timing is scripted, not measured, so nothing
    depends on the machine's load. ``drained``: after each chunk nothing more is waiting
    (the chunk is all the device sent until then, so the host clock can check the
    stream); else the next chunk is already waiting (a backlog: the clock cannot)."""

    def __init__(self, chunks: list[bytes], stalls_s=(), drained: bool = False):
        self.chunks, self.stalls_s, self.drained = list(chunks), list(stalls_s), drained
        self.i = self.pos = 0
        self.now_s = 0.0
        self.begun = False

    def _begin(self):
        if not self.begun:
            self.now_s += (self.stalls_s[self.i] if self.i < len(self.stalls_s) else 0.0) + 0.001
            self.begun = True

    @property
    def in_waiting(self):
        if self.i >= len(self.chunks):
            return 0
        self._begin()
        left = len(self.chunks[self.i]) - self.pos
        if left:
            return left
        self.i, self.pos, self.begun = self.i + 1, 0, False     # chunk i taken
        return 0 if self.drained or self.i >= len(self.chunks) else len(self.chunks[self.i])

    def read(self, n):
        if self.i >= len(self.chunks):
            time.sleep(0.001)          # the device has nothing more to say
            return b""
        if not self.begun:             # the next chunk waits for the next wake
            return b""
        data = self.chunks[self.i][self.pos:self.pos + n]
        self.pos += len(data)
        return data

    def clock(self):
        return self.now_s

    def close(self):
        pass


def scripted_source(chunks, stalls_s=(), sample_rate_hz=FS, drained=False):
    port = ScriptedPort(chunks, stalls_s, drained)
    return SerialSource(
        "scripted",
        921600,
        KvhCodec("a", "rate", "deg", "z", sample_rate_hz, MAX_RATE_DPH),
        opener=lambda: port,
        clock=port.clock,
    )


def split(data: bytes, sizes) -> list[bytes]:
    out, i = [], 0
    for s in sizes:
        out.append(data[i:i + s])
        i += s
    return [c for c in out if c] + ([data[i:]] if i < len(data) else [])


@pytest.mark.parametrize("stall_s", [0.01, 0.064, 0.1, 0.5, 2.0])
def test_host_stall_with_a_continuous_stream_makes_no_gap(stall_s, tmp_path):
    """The host does not read for 10 ms .. 2 s (frames split anywhere): the bytes arrive
    late but continuous, so every frame lands on its own slot; only the device's own drop
    (frame 300, the counter jumps) is a gap, and the capture's sidecar records no outage."""
    data, intact = stream(1000, {300: "drop"})
    chunks = split(data, [3000, 7777, 50, 4001, 9000, 36 * 200 + 5])
    stalls = [0.0, stall_s, stall_s, 0.0, stall_s, 2 * stall_s]
    src = scripted_source(chunks, stalls, sample_rate_hz=1000.0)           # a counter wrap: 128 ms
    archive = Archive(str(tmp_path / "arch"), src)
    blocks, t, rate, valid = collect(src, 1000)
    archive.close()
    with open(archive.capture_path + ".json") as fh:
        assert json.load(fh)["breaks"] == []
    ks = np.rint(rate[valid] / 3600).astype(int)
    assert list(ks) == intact and np.array_equal(np.rint(t[valid] * 1000).astype(int), ks)
    assert len(t) == 1000 and list(np.flatnonzero(~valid)) == [300]
    gaps = [e.message for b in blocks for e in b.events if e.kind == "gap"]
    assert gaps == ["1 sample(s) lost at t=0.300000 s (sequence counter)"]


def test_bytes_lost_give_the_exact_gap():
    """Bytes vanish (frames 400..449 and part of 399 and 450: an OS buffer overrun) and
    300 frames are garbled in place (frames 600..899, more than a counter wrap): the
    skipped bytes and the counter give exactly 52 and 300 lost samples."""
    frames = [frame_k(k) for k in range(1200)]
    garbled = bytes((i * 7) % 200 + 1 for i in range(300 * 36))     # never 0xFE: no false header
    data = b"".join(frames[:399]) + frames[399][:17] + frames[450][30:] + b"".join(frames[451:600]) \
        + garbled + b"".join(frames[900:])
    blocks, t, rate, valid = collect(scripted_source(split(data, [5000] * 9), [0.3] * 9), 1200)
    ks = np.rint(rate[valid] / 3600).astype(int)
    want = [k for k in range(1200) if not (399 <= k <= 450 or 600 <= k < 900)]
    assert list(ks) == want and np.array_equal(np.rint(t[valid] * FS).astype(int), ks)
    gaps = [e.message for b in blocks for e in b.events if e.kind == "gap"]
    assert gaps == ["52 sample(s) lost at t=1.995000 s (bytes skipped)",
                    "300 sample(s) lost at t=3.000000 s (bytes skipped)"]


def test_counters_equal_events_and_the_archive_and_nothing_after_the_cut_counts(tmp_path, monkeypatch):
    """A --duration-s run of 4.0 s (800 samples at 200 Hz) of a device that goes on
    sending, with CRC failures, drops and garbage before and after the cut: every counter
    equals the totals its events carry and what the archive holds, and the raw capture
    decodes to exactly samples.csv with the same counters."""
    from fogmon.pipeline import PipelineConfig as _args, run_pipeline
    from fogmon.sinks.base import Sink
    from fogmon.sources.files.capture import open_raw_capture

    faults = {k: "corrupt" for k in (10, 11, 150, 151, 152, 420, 777, 799, 800, 830, 900)}
    faults.update({k: "drop" for k in (50, 51, 500, 798, 850)})
    faults.update({k: "garbage" for k in (60, 790, 810)})
    data, intact = stream(1000, faults)

    class Events(Sink):
        def __init__(self):
            self.got = []

        def events(self, events):
            self.got += list(events)

    src = scripted_source(split(data, [997] * 40, ), [0.2] * 40)
    archive = Archive(str(tmp_path / "arch"), src)
    ev = Events()
    monkeypatch.setattr("fogmon.pipeline.run.LIVE_WALL_SLACK_S", 1e6)   # scripted device: no wall-clock stop
    summary = run_pipeline(src, _args(window_s=0.64, duration_s=4.0), sinks=[ev, archive])
    c = summary.counters
    assert summary.n_samples == 798                      # frames 798, 799 lost: the grid ends at 797
    inside = [k for k in intact if k < 798]
    rec = read_replay_log(archive.replay_log_path)
    assert list(np.rint(rec.rate_dph / 3600).astype(int)) == inside
    assert c["frames_ok"] == len(inside) == archive.counters["rows_written"]
    assert c["crc_errors"] == 7 and c["samples_missing"] == 798 - len(inside) == 10 and c["seq_gaps"] == 6
    crc = sum(int(e.message.split()[0]) for e in ev.got if e.kind == "crc_error")
    lost = sum(int(e.message.split()[0]) for e in ev.got if e.kind == "gap")
    assert (crc, lost, summary.event_counts["gap"]) == (c["crc_errors"], c["samples_missing"], c["seq_gaps"])
    replay = open_raw_capture(archive.capture_path)
    rb = list(replay.blocks())
    v = np.concatenate([b.valid for b in rb])
    assert sum(len(b) for b in rb) == summary.n_samples
    np.testing.assert_array_equal(np.concatenate([b.t_s for b in rb])[v], rec.t_s)
    assert {k: replay.counters[k] for k in replay.counters} == {k: c[k] for k in replay.counters}


# -- reading as fast as the device sends; idle costs nothing ------------------------------
class CappedPort:
    """A port holding ``data`` of which, like a tty, at most 4095 bytes are visible to
    ``in_waiting`` at a time (the kernel hands the rest over as the reader takes them);
    ``late``: after each full 4095 bytes taken, the kernel has not handed the next over
    yet when the reader looks (``in_waiting`` 0), but does while a read waits."""

    def __init__(self, data: bytes, late: bool = False):
        self.data, self.pos, self.late, self.held = data, 0, late, False

    @property
    def in_waiting(self):
        return 0 if self.held else min(len(self.data) - self.pos, 4095)

    def read(self, n):
        self.held = False
        out = self.data[self.pos:self.pos + min(n, self.in_waiting)]
        self.pos += len(out)
        self.held = self.late and len(out) == 4095
        return out


@pytest.mark.parametrize("late", [False, True])
def test_one_wake_takes_every_byte_waiting(late):
    """300 kB waiting (4 s of a 2 kHz format A stream) behind a 4 kB window, handed over
    at once or late: one wake of the reader takes all of it, as one item that says it
    found nothing more waiting."""
    data, _ = stream(8300)
    src = SerialSource("capped", 921600, KvhCodec("a", "rate", "deg", "z", 2000.0, MAX_RATE_DPH))
    (item,) = src._read(CappedPort(data, late))
    assert item[0] == "data" and item[1] == data and item[3] is True


def test_an_idle_device_leaves_the_consumer_waiting_not_polling():
    """A silent device: the consumer waits on its queue until the next idle block is due
    (one wait per idle block), never polls it in between (the clock advances only by the
    waits, so a polling loop would never get anywhere)."""
    import queue

    class Clock:
        now = 0.0

        def __call__(self):
            return self.now

    class Queue:
        def __init__(self, clock):
            self.clock, self.waits, self.polls = clock, [], 0

        def get(self, timeout):
            self.waits.append(timeout)
            self.clock.now += timeout
            raise queue.Empty

        def get_nowait(self):
            self.polls += 1
            if self.polls > 100:
                raise RuntimeError("the consumer polls its queue")
            raise queue.Empty

        def put(self, item):
            pass

    clock = Clock()
    src = SerialSource("silent", 921600, KvhCodec(), opener=lambda: ScriptedPort([]), clock=clock)
    src._q = q = Queue(clock)
    got = []
    for b in src.blocks():
        got.append(b)
        if len(got) == 20:
            break
    assert all(len(b) == 0 for b in got) and q.polls == 0
    assert len(q.waits) == 20 and np.allclose(q.waits, src.idle_s)


# -- the host clock: whole counter wraps lost without a byte gap --------------------------
def drained_source(chunks, codec, stalls_s):
    port = ScriptedPort(chunks, stalls_s, drained=True)
    return SerialSource("scripted", 921600, codec, opener=lambda: port, clock=port.clock, read_pause_s=0)


def replay_matches(archive, blocks, src):
    """The archive's raw capture decodes to the same grid, samples and counters."""
    archive.close()
    replay = open_raw_capture(archive.capture_path)
    rb = list(replay.blocks())
    for field in ("t_s", "valid"):
        np.testing.assert_array_equal(np.concatenate([getattr(b, field) for b in rb]),
                                      np.concatenate([getattr(b, field) for b in blocks]))
    assert {k: replay.counters[k] for k in replay.counters} == {k: src.counters[k] for k in replay.counters}
    return replay


def test_wraps_lost_without_a_byte_gap_are_placed_by_the_clock_and_replay_the_same(tmp_path):
    """A 1 kHz KVH read every 0.1 s loses frames 1000..1255 (two counter wraps) at a frame
    boundary: the counter and the bytes see nothing; the host clock places the 256
    samples within CLOCK_CONFIRM_S, counted (clock_wraps 2) and said (a gap event), every
    later sample is on its own slot, and the archive's raw capture replays to the same."""
    n, lost = 4000, set(range(1000, 1256))
    data = [b"".join(frame_k(k) for k in range(i, i + 100) if k not in lost) for i in range(0, n, 100)]
    src = drained_source(data, KvhCodec("a", "rate", "deg", "z", 1000.0, MAX_RATE_DPH), [0.099] * len(data))
    archive = Archive(str(tmp_path / "arch"), src)
    blocks, t, rate, valid = collect(src, n)
    ks = np.rint(rate[valid] / 3600).astype(int)
    slot = np.rint(t[valid] * 1000).astype(int)
    assert len(t) == n and src.counters["clock_wraps"] == 2 and src.counters["samples_missing"] == 256
    assert np.array_equal(slot[ks >= 1800], ks[ks >= 1800])          # on its slot again
    assert np.all(slot[ks >= 1256] >= ks[ks >= 1256] - 256)
    (gap,) = [e.message for b in blocks for e in b.events if e.kind == "gap"]
    assert gap.startswith("256 sample(s) lost at t=") and "host clock: 2 whole counter wrap(s)" in gap
    replay = replay_matches(archive, blocks, src)
    assert replay.counters["clock_wraps"] == 2


def test_an_implausible_counter_jump_is_no_gap_and_replays_the_same(tmp_path):
    """A ``lines`` board with an unbounded counter at 100 Hz: it restarts (0 after 299) and
    later jumps by 5000 (50 s within 0.1 s of host time; an hour would be plausible without
    a clock): neither allocates placeholders; both are implausible events, counted, and
    the raw capture replays to the same grid and counters."""
    seqs = list(range(300)) + list(range(500)) + list(range(5500, 5700))
    lines_ = [f"{s},{k * 0.001:.3f}\n".encode() for k, s in enumerate(seqs)]
    data = [b"".join(lines_[i:i + 10]) for i in range(0, len(lines_), 10)]
    src = drained_source(data, LinesCodec("seq,rate_dph", 100.0), [0.099] * len(data))
    archive = Archive(str(tmp_path / "arch"), src)
    blocks, t, rate, valid = collect(src, len(seqs))
    assert len(t) == len(seqs) and valid.all() and src.counters["implausible_gaps"] == 2
    msgs = [e.message for b in blocks for e in b.events if e.kind == "implausible"]
    assert [m.split(" at ")[0] for m in msgs] == ["the sequence counter went from 299 to 0",
                                                  "the sequence counter went from 499 to 5500"]
    replay_matches(archive, blocks, src)


def test_a_sidecar_outage_beyond_any_gap_is_one_line_naming_it(tmp_path):
    """A capture sidecar saying 1e9 samples were lost in an outage (a corrupt number) is
    one line naming the sidecar, not 1e9 placeholders."""
    data, _ = stream(100)
    cap = tmp_path / "raw.bin"
    cap.write_bytes(data)
    side = {"format": "fogmon capture v1", "kind": "serial", "protocol": "kvh-a", "axis": "z",
            "breaks": [{"offset": 36 * 50, "missing_est": 1e9, "elapsed_s": 1.0}]}
    (tmp_path / "raw.bin.json").write_text(json.dumps(side))
    with pytest.raises(FogmonError, match=r"raw\.bin\.json: field breaks: an outage of 1e\+09 samples"):
        list(open_raw_capture(str(cap)).blocks())
