"""`fogmon replay`: exit codes, one-line errors, the README's default command end to end."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fogmon.cli import main
from fogmon.davar.batch import dadev
from fogmon.recording import write_replay_log

from test_rerun_sink import read_scalars

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def small_log(tmp_path):
    fs, n = 50.0, 12_000
    rng = np.random.default_rng(5)
    t = np.arange(n) / fs
    rate = 2.0 + 60 * 0.1 * np.sqrt(fs) * rng.standard_normal(n)
    keep = np.ones(n, bool)
    keep[6000:6010] = False     # a 0.2 s time gap
    path = tmp_path / "run.csv"
    write_replay_log(path, t[keep], rate[keep], {"temp_c": 20 + t[keep] / 100}, {"sample_rate_hz": fs})
    r = rate.copy()
    r[~keep] = np.nan
    return path, r, fs


def test_replay_writes_rrd_equal_to_engine_and_summary(small_log, tmp_path, capsys):
    path, r, fs = small_log
    out = tmp_path / "o" / "run.rrd"
    rc = main(["replay", str(path), "--rrd", str(out), "--window-s", "40.96", "--hop-s", "10.24", "--no-progress"])
    assert rc == 0
    text = capsys.readouterr()
    assert "12000 samples at 50 Hz" in text.out and "(10 invalid/lost)" in text.out
    assert f"Wrote {out}" in text.out and "gap" in text.err
    ref = dadev(r, fs, 40.96, 10.24, valid=np.isfinite(r))
    _, logadev = read_scalars(str(out), "/dadev/log10_adev_dph")
    np.testing.assert_allclose(10 ** logadev, ref.adev_dph, rtol=1e-9)  # streaming engine == batch


def test_replay_taus_and_default_window(small_log, capsys):
    path, _, _ = small_log
    assert main(["replay", str(path), "--taus", "0.1,1,10", "--no-progress"]) == 0
    out = capsys.readouterr().out
    # default window: 12000 // 4 = 3000 -> 2048 samples = 40.96 s, hop window / 8
    assert "DADEV windows of 40.96 s every 5.12 s" in out
    rows = [l.split() for l in out.splitlines() if l.strip() and l.strip()[0].isdigit() and len(l.split()) == 6]
    assert [float(r[0]) for r in rows] == [0.1, 1.0, 10.0]


@pytest.mark.parametrize("argv, message", [
    (["replay", "/nonexistent/run.csv"], "/nonexistent/run.csv: no such file"),
    (["replay", "{log}", "--window-s", "100000"], "--window-s 100000 s is longer than the recording"),
    (["replay", "{bad}"], "line 4, column rate_dph: not a number: 'abc'"),
    (["replay", "{log}", "--connect", "rerun+http://127.0.0.1:1/proxy"], "no Rerun viewer listening at 127.0.0.1:1"),
    (["replay", "{log}", "--rrd", "/proc/x.rrd"], "--rrd /proc/x.rrd: cannot write"),
    (["replay", "{log}", "--rrd", "{tmp}"], "is a folder, give a file name like out/run.rrd"),
])
def test_replay_errors_are_one_line_exit_2(small_log, tmp_path, capsys, argv, message):
    bad = tmp_path / "bad.csv"
    bad.write_text("# fogmon replay log v1\ntime_s,rate_dph\n0,1\n0.01,abc\n")
    argv = [a.format(log=small_log[0], bad=bad, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize("argv", [["replay", "x.csv", "--taus", "1,nope"], ["replay", "x.csv", "--hop-s", "-1"],
                                  ["replay"]])
def test_replay_bad_usage_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].startswith("fogmon: error:")


def test_replay_help(capsys):
    with pytest.raises(SystemExit) as e:
        main(["replay", "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for opt in ("--rrd", "--connect", "--serve", "--window-s", "--hop-s", "--taus", "--realtime", "--protocol", "--dbc"):
        assert opt in out


def test_readme_default_command_end_to_end(tmp_path):
    """`fogmon replay replay_logs/lasergyro_z_100hz.csv --rrd out/lasergyro.rrd`, as a user runs it."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, "-m", "fogmon", "replay", str(ROOT / "replay_logs/lasergyro_z_100hz.csv"),
                        "--rrd", "out/lasergyro.rrd"], cwd=tmp_path, capture_output=True, text=True, env=env,
                       timeout=240)
    assert p.returncode == 0, p.stderr
    assert "184718 samples at 100 Hz = 1847.18 s" in p.stdout
    assert "Wrote out/lasergyro.rrd" in p.stdout
    ts, logadev = read_scalars(str(tmp_path / "out/lasergyro.rrd"), "/dadev/log10_adev_dph")
    assert logadev.shape == (38, 14)   # windows of 32768 samples every 4096; m = 1 .. 8192 (0.01 .. 81.92 s)
    # the real gyro's published character (PROVENANCE.txt): OADEV(z) 34 deg/h at 0.01 s
    line = next(l for l in p.stdout.splitlines() if l.split()[:1] == ["0.01"])
    assert abs(float(line.split()[1]) - 34.17) < 0.01


@pytest.mark.filterwarnings("ignore:RRD file has no footer")
def test_replay_serve_feeds_a_late_viewer_and_stops_on_ctrl_c(small_log, tmp_path):
    """--serve (localhost) keeps serving after the replay; a viewer connecting late still
    gets everything the file sink got; Ctrl-C then ends it with exit 0."""
    from test_rerun_sink import _free_port
    from fogmon.sinks.rerun_sink import stop_process_group

    port = _free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    file_ = tmp_path / "f.rrd"
    p = subprocess.Popen([sys.executable, "-m", "fogmon", "replay", str(small_log[0]), "--serve", "--port", str(port),
                          "--rrd", str(file_), "--window-s", "40.96", "--no-progress", "--quiet"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    recv = None
    try:
        line = ""
        while "still serving" not in line:
            line = p.stderr.readline()
            assert line or p.poll() is None, "replay ended before serving"
        got = tmp_path / "viewer.rrd"
        recv = subprocess.Popen([str(Path(sys.executable).parent / "rerun"), "--port", str(_free_port()), "--save",
                                 str(got), f"rerun+http://127.0.0.1:{port}/proxy"], start_new_session=True,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        want = read_scalars(str(file_), "/dadev/log10_adev_dph")
        deadline = time.monotonic() + 30
        while True:
            time.sleep(0.5)
            have = read_scalars(str(got), "/dadev/log10_adev_dph") if got.exists() else ([], [])
            if len(have[0]) == len(want[0]) or time.monotonic() > deadline:
                break
        np.testing.assert_array_equal(have[1], want[1])
        p.send_signal(signal.SIGINT)
        assert p.wait(timeout=30) == 0
    finally:
        if recv is not None:
            stop_process_group(recv)
        if p.poll() is None:
            p.kill()
