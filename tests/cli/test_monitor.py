"""`fogmon monitor` on a fake 1 kHz KVH DSP-1760 (pty): archive, .rrd, summary, errors;
replaying its archive gives the same DADEV the live run logged."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO
from helpers.doubles import archive_in
from helpers.rrd import read_event_messages, read_scalars

from fogmon.cli import main
from fogmon.formats.replay_log import read_replay_log
from fogmon.sources.files.capture import open_raw_capture


def test_monitor_fake_kvh_archives_and_logs_the_same_as_a_replay(fake_kvh, tmp_path, capsys):
    runs, rrd = tmp_path / "runs", tmp_path / "live.rrd"
    runs.mkdir()
    rc = main(["monitor", "--serial", fake_kvh, "--protocol", "kvh-a", "--duration-s", "2", "--archive", str(runs),
               "--axis", "z", "--rrd", str(rrd), "--window-s", "0.512", "--hop-s", "0.128", "--no-progress"])
    assert rc == 0
    arch = Path(archive_in(runs))                     # runs/fogmon-archive-YYYYmmddTHHMMSSZ
    out = capsys.readouterr().out
    # 2 s = 2000 samples; 1999 when the run's last frame is one of the bad ones (its slot is only
    # known to be lost from the next frame, which lies after the cut and is not read)
    n = int(re.search(r"(\d+) samples at 1000 Hz", out).group(1))
    assert n in (1999, 2000) and f"Wrote archive {arch}" in out
    rec = read_replay_log(arch / "samples-0001.csv")
    assert rec.sample_rate_hz == 1000.0 and list(rec.aux) == ["temp_c"] and np.all(rec.aux["temp_c"] == 31)
    assert len(rec) <= n and rec.t_s[-1] == pytest.approx((n - 1) / 1000)
    # N of the fake device is 0.05 deg/sqrt(h): the whole-run fit finds it
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("N_dpsh"))
    assert abs(float(line.split("=")[1].split()[0]) - 0.05) < 0.005
    assert not (tmp_path / "live-0001.rrd").exists()   # --rrd X writes X (pieces only with --rotate-s)
    t_live, live = read_scalars(str(rrd), "/dadev/log10_adev_dph")
    assert live.shape == (12, 8)      # (n - 512) // 128 + 1 windows; m = 1 .. 128
    t_rate, _ = read_scalars(str(rrd), "/rate/rate_dph")
    assert len(t_rate) <= 200         # 1 kHz shown as means of 10 samples
    crc = int(next(ln for ln in out.splitlines() if ln.strip().startswith("crc_errors")).split()[1])
    assert crc >= 2                    # 2 s at 1 kHz, every 500th frame bad
    texts = read_event_messages(str(rrd), "/events")
    assert sum(int(x.split()[1]) for x in texts if x.startswith("crc_error:")) == crc
    # the raw capture ends where samples.csv does (the --duration-s cut) and decodes to the same counters
    raw = open_raw_capture(sorted(str(p) for p in arch.glob("raw-*.bin")))
    rb = list(raw.blocks())
    assert sum(len(b) for b in rb) == n
    np.testing.assert_allclose(np.concatenate([b.t_s[b.valid] for b in rb]), rec.t_s, rtol=0, atol=1e-9)
    summary = {ln.split()[0]: int(ln.split()[1]) for ln in out.split("Counters:")[1].splitlines()[1:]
               if len(ln.split()) == 2 and ln.split()[1].isdigit()}
    assert all(summary[k] == v for k, v in raw.counters.items()), (summary, raw.counters)
    replay = tmp_path / "replay.rrd"
    assert main(["replay", str(arch), "--rrd", str(replay), "--window-s", "0.512",
                 "--hop-s", "0.128", "--no-progress", "--quiet"]) == 0
    t_rep, rep = read_scalars(str(replay), "/dadev/log10_adev_dph")
    np.testing.assert_allclose(t_rep, t_live, atol=1e-9)
    np.testing.assert_allclose(rep, live, rtol=1e-9)   # the archive stores 12 significant digits


def test_monitor_needs_a_source(capsys):
    assert main(["monitor", "--duration-s", "1"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == "fogmon monitor: error: give exactly one of --serial PORT or --can CHANNEL"


def test_monitor_bad_port_is_one_line_and_leaves_no_archive(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["monitor", "--serial", str(tmp_path / "ttyNONE"), "--duration-s", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"fogmon monitor: error: --serial {tmp_path / 'ttyNONE'}: cannot open")
    assert len(err.splitlines()) == 1 and list(tmp_path.iterdir()) == []


def test_monitor_help(capsys):
    with pytest.raises(SystemExit) as e:
        main(["monitor", "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for opt in ("--serial", "--can", "--archive", "--duration-s", "--rrd", "--connect", "--serve", "--bind"):
        assert opt in out


@pytest.mark.timeout(1200)
def test_ctrl_c_stops_cleanly_with_summary_rrd_and_archive(fake_kvh, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    runs, rrd = tmp_path / "runs", tmp_path / "c.rrd"
    runs.mkdir()
    p = subprocess.Popen([sys.executable, "-m", "fogmon", "monitor", "--serial", fake_kvh, "--protocol", "kvh-a",
                          "--axis", "z", "--archive", str(runs), "--rrd", str(rrd), "--window-s", "0.512",
                          "--no-progress"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)

    def csv() -> Path:
        return Path(archive_in(runs), "samples-0001.csv")

    try:
        deadline = time.monotonic() + 600  # failure guard only (a cold numba compile under load): we wait for data
        while not csv().exists() or csv().stat().st_size < 40_000:
            assert time.monotonic() < deadline and p.poll() is None, p.stderr.read() if p.poll() is not None else ""
            time.sleep(0.1)
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    assert "fogmon: interrupted (Ctrl-C)" in out and "Traceback" not in err
    n = int(next(ln for ln in out.splitlines() if "samples at 1000 Hz" in ln).split()[0])
    arch = Path(archive_in(runs))
    rec = read_replay_log(arch / "samples-0001.csv")  # complete rows only, readable
    raw = list(open_raw_capture(str(arch / "raw-0001.bin")).blocks())
    assert sum(len(b) for b in raw) == n            # what was read before the stop is archived and counted
    np.testing.assert_allclose(np.concatenate([b.t_s[b.valid] for b in raw]), rec.t_s, rtol=0, atol=1e-9)
    t, _ = read_scalars(str(rrd), "/rate/rate_dph")
    assert len(t) > 0


def test_monitor_three_axis_kvh_archives_every_axis_and_replays_the_same(fake_kvh, tmp_path, capsys):
    """Issue 14: one port, one process, one archive: a three-axis KVH 1760 (a bad CRC every
    500th frame) monitored without --axis; the archive holds every axis exactly as the raw
    capture decodes it, and replaying the archive gives each axis's live DADEV."""
    runs, rrd = tmp_path / "runs", tmp_path / "live.rrd"
    runs.mkdir()
    args = ["--window-s", "0.512", "--hop-s", "0.128", "--no-progress"]
    assert main(["monitor", "--serial", fake_kvh, "--protocol", "kvh-a", "--duration-s", "2", "--archive", str(runs),
                 "--rrd", str(rrd), *args]) == 0
    arch = Path(archive_in(runs))
    out = capsys.readouterr().out
    assert "IEEE-952 noise coefficients per axis" in out
    rec = read_replay_log(arch / "samples-0001.csv")
    assert rec.axes == ("x", "y", "z") and {"accel_x_g", "accel_z_g", "temp_c"} <= set(rec.aux)
    raw = open_raw_capture(sorted(str(p) for p in arch.glob("raw-*.bin")))
    rb = list(raw.blocks())
    assert raw.axes == rec.axes
    rate = np.concatenate([b.rate_dph for b in rb])
    ok = np.concatenate([b.valid for b in rb]).all(axis=1)
    assert (~ok).sum() >= 2                                   # the bad-CRC frames: lost on every axis
    np.testing.assert_allclose(rec.rate_dph, rate[ok], rtol=1e-11)  # 12 significant digits in the CSV
    live = {a: read_scalars(str(rrd), f"/axis/{a}/dadev/log10_adev_dph") for a in rec.axes}
    assert all(v[1].shape == (12, 8) for v in live.values())
    assert main(["replay", str(arch), "--rrd", str(tmp_path / "replay.rrd"), *args, "--quiet"]) == 0
    for a, (t_live, adev_live) in live.items():
        t_rep, adev_rep = read_scalars(str(tmp_path / "replay.rrd"), f"/axis/{a}/dadev/log10_adev_dph")
        np.testing.assert_allclose(t_rep, t_live, atol=1e-9)
        np.testing.assert_allclose(adev_rep, adev_live, rtol=1e-9)
    assert not np.allclose(live["x"][1], live["z"][1])        # the axes carry their own noise
