"""Serial source against fake KVH devices on loop:// and on a pty: exact accounting of
corrupted, truncated, dropped frames and garbage; unplug and replug with the archive
keeping every sample sent while connected; replay of the raw capture gives the same
samples."""
import os
import threading
import time

import numpy as np
import pytest
import serial

from fogmon.recording import read_replay_log
from fogmon.sinks.archive import Archive, run_archived
from fogmon.sources.kvh import KvhCodec
from fogmon.sources.replay import open_raw_capture
from fogmon.sources.serial_source import SerialSource
from sources_fake_device import MAX_RATE_DPH, FakeKvh, open_pty, stream, write_all

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
    stop = threading.Event()

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
        time.sleep(0.3)
        stop.set()

    th = threading.Thread(target=device)
    th.start()
    blocks = []

    def on_block(b):
        blocks.append(b)
        if stop.is_set():
            src.close()

    counters = run_archived(src, archive, duration_s=15, on_block=on_block)
    th.join()
    dev.close()
    rec = read_replay_log(archive.replay_log_path)
    ks = np.rint(rec.rate_dph / 3600).astype(int)
    assert list(ks) == dev.sent, (counters, [(e.t_s, e.kind, e.message) for b in blocks for e in b.events])                         # every sample sent while connected
    k0 = dev.sent[0]
    assert np.array_equal(np.rint(rec.t_s * FS).astype(int), ks - k0)   # outage kept as a gap of the right length
    assert counters["disconnects"] == 1 and counters["reconnects"] == 1
    assert counters["samples_missing"] == dev.sent[-1] - k0 + 1 - len(dev.sent)
    kinds = [e.kind for b in blocks for e in b.events]
    assert kinds.count("disconnect") == 1 and kinds.count("reconnect") == 1 and "gap" in kinds
    # the raw capture decodes to exactly the same samples
    replay = open_raw_capture(archive.capture_path)
    rb = list(replay.blocks())
    t = np.concatenate([b.t_s for b in rb])
    v = np.concatenate([b.valid for b in rb])
    r = np.concatenate([b.rate_dph for b in rb])
    np.testing.assert_array_equal(t[v], rec.t_s)
    np.testing.assert_array_equal(r[v], rec.rate_dph)
