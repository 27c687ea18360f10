"""The Parquet replay log: conversion from every recording kind, the same blocks and
numbers as the CSV, bounded row-group reading, and a live archive that survives SIGKILL."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from helpers import REPO
from helpers.doubles import archive_in

from fogmon.cli import main
from fogmon.formats.archive import piece_files
from fogmon.formats.parquet_log import META_KEY, read_parquet_log
from fogmon.formats.replay_log import read_replay_log, write_replay_log
from fogmon.sources.files.capture import open_raw_capture
from fogmon.sources.files.parquet import ParquetLogSource
from fogmon.sources.files.replay_log import ReplayLogSource
from fogmon.sources.open import open_replay_source

ROOT = REPO


def _blocks(src):
    return list(src.blocks())


def _gappy_log(path, n=50_000, sample_rate_hz=100.0):
    rng = np.random.default_rng(3)
    t = np.arange(n) / sample_rate_hz
    keep = np.ones(n, bool)
    keep[1000:1040] = keep[20_000:20_001] = False
    write_replay_log(path, t[keep], rng.standard_normal(n)[keep] * 5 + 1, {"temp_c": 25 + t[keep] / 1e3},
                     {"sample_rate_hz": sample_rate_hz, "sensor": "test gyro"})


def test_convert_csv_gives_the_same_blocks_and_counters(tmp_path, capsys):
    csv, pqf = tmp_path / "a.csv", tmp_path / "a.parquet"
    _gappy_log(csv)
    assert main(["convert", str(csv), str(pqf)]) == 0
    assert "wrote 49959 samples at 100 Hz" in capsys.readouterr().out
    a, b = ReplayLogSource(str(csv)), ParquetLogSource(str(pqf))
    assert (a.n_samples, a.t_first_s, a.t_last_s, a.aux_names) == (b.n_samples, b.t_first_s, b.t_last_s, b.aux_names)
    ba, bb = _blocks(a), _blocks(b)
    assert [len(x) for x in ba] == [len(x) for x in bb]
    for x, y in zip(ba, bb, strict=True):
        np.testing.assert_array_equal(x.t_s, y.t_s)
        np.testing.assert_array_equal(x.rate_dph, y.rate_dph)
        np.testing.assert_array_equal(x.valid, y.valid)
        np.testing.assert_array_equal(x.aux["temp_c"], y.aux["temp_c"])
        assert [e.kind for e in x.events] == [e.kind for e in y.events]
    assert a.counters == b.counters
    info = pq.ParquetFile(pqf)
    assert info.metadata.num_row_groups == 1      # 65,536 rows per row group
    meta = __import__("json").loads(info.metadata.metadata[META_KEY])
    assert meta["meta"]["sample_rate_hz"] == "100" and meta["units"]["rate_dph"] == "deg/h"
    assert meta["counters"]["samples"] == 49959
    rec_a, rec_b = read_replay_log(csv), read_replay_log(pqf)   # explain, sim --like, ... read it too
    np.testing.assert_array_equal(rec_a.rate_dph, rec_b.rate_dph)
    assert rec_b.sample_rate_hz == 100.0 and rec_b.meta["sensor"] == "test gyro"
    # and back to CSV: the same rows
    back = tmp_path / "b.csv"
    assert main(["convert", str(pqf), str(back)]) == 0
    np.testing.assert_array_equal(read_replay_log(back).t_s, rec_a.t_s)


def test_replay_of_parquet_equals_replay_of_csv(tmp_path, capsys):
    csv, pqf = tmp_path / "a.csv", tmp_path / "a.parquet"
    _gappy_log(csv)
    assert main(["convert", str(csv), str(pqf)]) == 0
    capsys.readouterr()
    outs = []
    for f in (csv, pqf):
        assert main(["replay", str(f), "--no-progress", "--window-s", "81.92"]) == 0
        out = capsys.readouterr().out.split("\n", 1)[1]            # after the line naming the source
        outs.append([line for line in out.splitlines() if " wall" not in line])
    assert outs[0] == outs[1]


def test_bad_parquet_input_is_one_line(tmp_path, capsys):
    import pyarrow as pa
    bad = tmp_path / "bad.parquet"
    pq.write_table(pa.table({"time_s": [0.0, 0.01, 0.01], "rate_dph": [1.0, 2.0, 3.0]}), bad)
    assert main(["replay", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.parquet: row 3, column time_s: time repeats" in err and "Traceback" not in err
    nan = tmp_path / "nan.parquet"
    pq.write_table(pa.table({"time_s": [0.0, 0.01, 0.02], "rate_dph": [1.0, float("nan"), 3.0]}), nan)
    assert main(["convert", str(nan), str(tmp_path / "x.parquet")]) == 2
    assert "nan.parquet: row 2, column rate_dph: nan is not a finite number" in capsys.readouterr().err
    assert not (tmp_path / "x.parquet").exists() and not (tmp_path / "x.parquet.tmp").exists()
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"not parquet at all")
    assert main(["replay", str(junk)]) == 2
    assert "junk.parquet: not a readable Parquet file" in capsys.readouterr().err


def _log_with(path, bad: dict[int, str], n=2000):
    """A replay log of ``n`` samples at 100 Hz whose rows ``bad`` (index -> rate text) are bad."""
    rate = np.random.default_rng(1).normal(0, 3, n)
    path.write_text("# sample_rate_hz: 100\ntime_s,rate_dph\n"
                    + "".join(f"{i / 100:.2f},{bad.get(i, f'{v:.4f}')}\n" for i, v in enumerate(rate)))


def test_convert_counts_every_sample_it_leaves_out(tmp_path, capsys):
    """Implausible samples (beyond the plausibility gate) and bad rows skipped with
    --tolerate-bad-rows are not written (a replay log holds valid samples only): each
    count is printed with its reason and kept in a Parquet output's counters, and the
    output reads back with those samples as a time gap."""
    src = tmp_path / "some.csv"
    _log_with(src, {100: "1e9", 101: "1e9", 102: "1e9", 103: "1e9", 104: "1e9", 500: "nan"})
    for out in (tmp_path / "o.parquet", tmp_path / "o.csv"):
        assert main(["convert", str(src), str(out), "--tolerate-bad-rows"]) == 0
        assert capsys.readouterr().out == (f"fogmon convert: wrote 1994 samples at 100 Hz from replay log some.csv "
                                           f"to {out}; 6 invalid or lost samples left out (samples_missing 1, "
                                           f"skipped_rows 1, implausible_samples 5)\n")
        back = ReplayLogSource(str(out)) if out.suffix == ".csv" else ParquetLogSource(str(out))
        blocks = _blocks(back)
        assert sum(len(b) for b in blocks) == 2000 and sum(int(np.count_nonzero(~b.valid)) for b in blocks) == 6
    counters = __import__("json").loads(pq.ParquetFile(tmp_path / "o.parquet").metadata.metadata[META_KEY])["counters"]
    assert {k: counters[k] for k in ("rows_written", "invalid_samples_left_out", "implausible_samples",
                                     "skipped_rows", "samples_missing")} == {
        "rows_written": 1994, "invalid_samples_left_out": 6, "implausible_samples": 5, "skipped_rows": 1,
        "samples_missing": 1}


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_convert_refuses_an_output_without_samples(tmp_path, capsys, suffix):
    """Every rate implausible: one line saying why, exit 2, and no output file (not even
    a header-only one that `fogmon replay` would refuse), no temporary file left."""
    src = tmp_path / "huge.csv"
    _log_with(src, {i: "1e12" for i in range(300)}, n=300)
    out = tmp_path / f"o{suffix}"
    assert main(["convert", str(src), str(out)]) == 2
    assert capsys.readouterr().err == (f"fogmon convert: error: {src}: no sample to write, nothing written to OUT "
                                       f"{out}: of 300 samples, 300 invalid or lost (implausible_samples 300); "
                                       f"--max-rate-dph sets the plausibility gate\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["huge.csv"]
    assert main(["convert", str(src), str(out), "--max-rate-dph", "1e13"]) == 0     # a gate that lets them through
    assert len(read_replay_log(out).t_s) == 300


def test_convert_checks_the_space_after_a_first_block_without_valid_samples(tmp_path, capsys, monkeypatch):
    """The free space is checked at the first block that writes rows (here the second:
    the first 8192 rates are implausible), not only when the very first block does."""
    import fogmon.outputs

    src = tmp_path / "late.csv"
    _log_with(src, {i: "1e12" for i in range(9000)}, n=20_000)
    monkeypatch.setattr(fogmon.outputs, "free_bytes", lambda path: 1000)
    out = tmp_path / "o.csv"
    assert main(["convert", str(src), str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"fogmon convert: error: OUT {out}: ") and " more rows of " in err and err.count("\n") == 1
    assert not out.exists()


def test_convert_raw_capture_keeps_its_sidecar_facts(tmp_path, capsys):
    from fogmon.sources.codecs.kvh import encode_frame
    raw = tmp_path / "raw.bin"
    rng = np.random.default_rng(0)
    frames = [encode_frame("a", i % 128, (0.0, 0.0, 1e-7 * rng.standard_normal()), temp_c=30) for i in range(3000)]
    del frames[1500:1503]                                         # 3 frames lost
    raw.write_bytes(b"".join(frames))
    out = tmp_path / "raw.parquet"
    assert main(["convert", str(raw), str(out), "--protocol", "kvh-a", "--axis", "z"]) == 0
    capsys.readouterr()
    rec = read_parquet_log(str(out))
    ref = [b for b in open_raw_capture(str(raw), {"protocol": "kvh-a", "axis": "z"}).blocks()]
    np.testing.assert_array_equal(rec.t_s, np.concatenate([b.t_s[b.valid] for b in ref]))
    info = __import__("json").loads(pq.ParquetFile(out).metadata.metadata[META_KEY])
    assert "raw capture raw.bin" in info["source"] and info["counters"]["seq_gaps"] == 1


@pytest.fixture
def fake_kvh():
    p = subprocess.Popen([sys.executable, str(REPO / "tests" / "helpers" / "fake_kvh.py"), "60"],
                         stdout=subprocess.PIPE, text=True)
    try:
        yield p.stdout.readline().strip()
    finally:
        p.kill()
        p.wait(timeout=10)


@pytest.mark.timeout(600)
def test_sigkilled_parquet_archive_loses_at_most_the_row_group_being_filled(tmp_path):
    """A device sends exactly 2,250 frames and falls silent; once the monitor has put them
    all in its raw capture and four 500-sample row groups are on disk, it is SIGKILLed:
    the Parquet archive holds exactly the first 2,000 samples (the 250 of the row group
    being filled are lost, less than one row group) and replays."""
    import select
    import threading

    from helpers.fake_device import has_open, open_pty

    from fogmon.sources.codecs.kvh import encode_frame
    n_sent, rows = 2250, 500
    master, slave, port = open_pty()
    rng = np.random.default_rng(1)
    data = memoryview(b"".join(encode_frame("a", i % 128, (0.0, 0.0, 1e-7 * rng.standard_normal()), temp_c=30)
                               for i in range(n_sent)))
    stop = threading.Event()
    runs = tmp_path / "runs"
    runs.mkdir()

    def files() -> tuple[Path, Path]:
        arch = Path(archive_in(runs))
        return arch / "samples-0001.parquet.parts", arch / "raw-0001.bin"

    def send():
        view = data
        # pyserial's open() flushes what the port held, after the descriptor shows in /proc:
        # a byte outside any frame, sent until the monitor has captured one, marks the flush done
        while not (files()[1].exists() and files()[1].stat().st_size) and not stop.is_set():
            if has_open(p.pid, port):
                os.write(master, b"\0")
            stop.wait(0.05)
        while view and not stop.is_set():     # the pty holds ~20 kB: write as the monitor reads
            if select.select([], [master], [], 0.1)[1]:
                view = view[os.write(master, view):]

    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.Popen([sys.executable, "-m", "fogmon", "monitor", "--serial", port, "--protocol", "kvh-a",
                          "--axis", "z", "--archive", str(runs), "--archive-format", "parquet",
                          "--row-group-s", str(rows / 1000), "--window-s", "0.512", "--no-progress", "--quiet"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        deadline = time.monotonic() + 500  # a guard against a hang (cold numba compile under load), not a timing
        # synchronise on data: every frame in the raw capture, four row groups on disk
        while not ((raw := files()[1]).exists() and raw.stat().st_size >= len(data)
                   and raw.read_bytes().endswith(bytes(data)) and len(list(files()[0].glob("*.parquet"))) == 4):
            assert time.monotonic() < deadline and p.poll() is None, p.stderr.read() if p.poll() is not None else ""
            time.sleep(0.05)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=30)
    finally:
        stop.set()
        if p.poll() is None:
            p.kill()
        sender.join(timeout=10)
        os.close(master)
        os.close(slave)
    arch, raw = Path(archive_in(runs)), files()[1]
    pieces = piece_files(str(arch))
    assert [os.path.basename(f) for f in pieces] == [f"part-00000{i}.parquet" for i in range(1, 5)]
    rec = read_parquet_log(pieces)
    t_raw = np.concatenate([b.t_s[b.valid] for b in open_raw_capture(str(raw)).blocks()])
    assert len(t_raw) == n_sent and len(rec) == 4 * rows           # lost: 250 samples < one row group
    np.testing.assert_array_equal(rec.t_s, t_raw[:len(rec)])
    src = open_replay_source(str(arch), None)                       # the killed archive replays
    assert sum(int(b.valid.sum()) for b in src.blocks()) == len(rec)
    assert main(["replay", str(arch), "--window-s", "0.512", "--no-progress", "--quiet"]) == 0


def test_monitor_parquet_archive_joined_at_the_end(fake_kvh, tmp_path, capsys):
    assert main(["monitor", "--serial", fake_kvh, "--protocol", "kvh-a", "--duration-s", "1.5", "--archive",
                 str(tmp_path), "--archive-format", "parquet", "--row-group-s", "0.4", "--window-s", "0.256",
                 "--no-progress", "--axis", "z", "--quiet"]) == 0
    arch = Path(archive_in(tmp_path))
    assert sorted(os.listdir(arch)) == ["raw-0001.bin", "raw-0001.bin.json", "samples-0001.parquet"]
    pf = pq.ParquetFile(arch / "samples-0001.parquet")
    assert pf.metadata.num_row_groups == 4                            # 400 + 400 + 400 + the rest
    rec = read_parquet_log(str(arch / "samples-0001.parquet"))
    raw = list(open_raw_capture(str(arch / "raw-0001.bin")).blocks())
    np.testing.assert_allclose(rec.t_s, np.concatenate([b.t_s[b.valid] for b in raw]), rtol=0, atol=1e-9)
