"""`fogmon replay`: exit codes, one-line errors, the README's default command end to end;
stop signals; the --serve server's life; sidecars checked field by field and confined to
their folder."""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO
from helpers.rrd import read_scalars

from fogmon.cli import main
from fogmon.davar.batch import dadev
from fogmon.formats.replay_log import write_replay_log

ROOT = REPO


def fogmon_process(*argv, **kw):
    """`python -m fogmon ...` in its own session (the process_groups fixture kills it)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "fogmon", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, start_new_session=True, **kw)


@pytest.fixture
def small_log(tmp_path):
    sample_rate_hz, n = 50.0, 12_000
    rng = np.random.default_rng(5)
    t = np.arange(n) / sample_rate_hz
    rate = 2.0 + 60 * 0.1 * np.sqrt(sample_rate_hz) * rng.standard_normal(n)
    keep = np.ones(n, bool)
    keep[6000:6010] = False     # a 0.2 s time gap
    path = tmp_path / "run.csv"
    write_replay_log(path, t[keep], rate[keep], {"temp_c": 20 + t[keep] / 100}, {"sample_rate_hz": sample_rate_hz})
    r = rate.copy()
    r[~keep] = np.nan
    return path, r, sample_rate_hz


def test_replay_writes_rrd_equal_to_engine_and_summary(small_log, tmp_path, capsys):
    path, r, sample_rate_hz = small_log
    out = tmp_path / "run.rrd"
    rc = main(["replay", str(path), "--rrd", str(out), "--window-s", "40.96", "--hop-s", "10.24", "--no-progress"])
    assert rc == 0
    text = capsys.readouterr()
    assert "12000 samples at 50 Hz" in text.out and "(10 invalid/lost)" in text.out
    assert f"Wrote {out}" in text.out and "gap" in text.err
    ref = dadev(r, sample_rate_hz, 40.96, 10.24, valid=np.isfinite(r))
    _, logadev = read_scalars(str(out), "/dadev/log10_adev_dph")
    np.testing.assert_allclose(10 ** logadev, ref.adev_dph, rtol=1e-9)  # streaming engine == batch


def test_replay_taus_and_default_window(small_log, capsys):
    path, _, _ = small_log
    assert main(["replay", str(path), "--taus", "0.1,1,10", "--no-progress"]) == 0
    out = capsys.readouterr().out
    # default window: 12000 // 4 = 3000 -> 2048 samples = 40.96 s, hop window / 8
    assert "DADEV windows of 40.96 s every 5.12 s" in out
    rows = [ln.split() for ln in out.splitlines() if ln.strip() and ln.strip()[0].isdigit() and len(ln.split()) == 6]
    assert [float(r[0]) for r in rows] == [0.1, 1.0, 10.0]


@pytest.mark.parametrize("argv, message", [
    (["replay", "/nonexistent/run.csv"], "/nonexistent/run.csv: no such file"),
    (["replay", "{log}", "--window-s", "100000"], "--window-s 100000 s is longer than the recording"),
    (["replay", "{bad}"], "line 4, column rate_dph: not a number: 'abc'"),
    (["replay", "{log}", "--connect", "rerun+http://127.0.0.1:1/proxy"], "no Rerun viewer listening at 127.0.0.1:1"),
    (["replay", "{log}", "--rrd", "/proc/x.rrd"], "--rrd /proc/x.rrd: cannot write"),
    (["replay", "{log}", "--rrd", "{tmp}"], "is a folder, give a file name"),
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
    err = capsys.readouterr().err
    assert err.startswith("fogmon replay: error:") and err.endswith(" (see fogmon replay --help)\n")
    assert err.count("\n") == 1                     # one line, not argparse's usage block before it


def test_replay_help(capsys):
    with pytest.raises(SystemExit) as e:
        main(["replay", "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for opt in ("--rrd", "--connect", "--serve", "--window-s", "--hop-s", "--taus", "--realtime", "--protocol",
                "--dbc"):
        assert opt in out


def test_readme_default_command_end_to_end(tmp_path):
    """`fogmon replay replay_logs/lasergyro_z_100hz.csv --rrd lasergyro.rrd`, as a user runs it."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, "-m", "fogmon", "replay", str(ROOT / "replay_logs/lasergyro_z_100hz.csv"),
                        "--rrd", "lasergyro.rrd"], cwd=tmp_path, capture_output=True, text=True, env=env,
                       timeout=240)
    assert p.returncode == 0, p.stderr
    assert "184718 samples at 100 Hz = 1847.18 s" in p.stdout
    assert "Wrote lasergyro.rrd" in p.stdout
    ts, logadev = read_scalars(str(tmp_path / "lasergyro.rrd"), "/dadev/log10_adev_dph")
    assert logadev.shape == (38, 14)   # windows of 32768 samples every 4096; m = 1 .. 8192 (0.01 .. 81.92 s)
    # the real gyro's published character (PROVENANCE.txt): OADEV(z) 34 deg/h at 0.01 s, 34.17
    # over the whole record, 33.34 with the vehicle's sway (platform motion, 6.1 %) kept out
    line = next(ln for ln in p.stdout.splitlines() if ln.split()[:1] == ["0.01"])
    assert abs(float(line.split()[1]) - 33.34) < 0.01
    assert "platform motion: 32 span(s), 11200 samples (6.1 %) kept out" in p.stdout


@pytest.mark.filterwarnings("ignore:RRD file has no footer")   # the viewer's file is read while it writes
def test_replay_serve_feeds_a_late_viewer_and_stops_on_ctrl_c(small_log, tmp_path, process_groups):
    """--serve (localhost) keeps serving after the replay; a viewer connecting late still
    gets everything the file sink got; Ctrl-C then ends it with exit 0 and stops the server."""
    from helpers.net import free_port, listening, wait_until
    port = free_port()
    file_ = tmp_path / "f.rrd"
    p = fogmon_process("replay", str(small_log[0]), "--serve", "--port", str(port), "--rrd", str(file_),
                       "--window-s", "40.96", "--no-progress", "--quiet")
    process_groups.append(p)
    line = ""
    while "still serving" not in line:
        line = p.stderr.readline()
        assert line or p.poll() is None, "replay ended before serving"
    got = tmp_path / "viewer.rrd"
    process_groups.append(subprocess.Popen(
        [str(Path(sys.executable).parent / "rerun"), "--port", str(free_port()), "--save", str(got),
         f"rerun+http://127.0.0.1:{port}/proxy"], start_new_session=True, stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL))
    want = read_scalars(str(file_), "/dadev/log10_adev_dph")

    def viewer_has_all():
        try:
            return len(read_scalars(str(got), "/dadev/log10_adev_dph")[0]) == len(want[0])
        except (OSError, ValueError, RuntimeError):   # not written yet, no recording in it yet, or a frame cut
            return False

    wait_until(viewer_has_all, "the late viewer did not get every window")
    np.testing.assert_array_equal(read_scalars(str(got), "/dadev/log10_adev_dph")[1], want[1])
    p.send_signal(signal.SIGINT)
    assert p.wait(timeout=30) == 0
    assert not listening(port)


@pytest.fixture
def gap_log(tmp_path):
    """60 s at 50 Hz of white noise with a 0.2 s time gap at t = 1 s (its event says the replay is under way)."""
    sample_rate_hz, n = 50.0, 3000
    t = np.arange(n) / sample_rate_hz
    keep = (t < 1.0) | (t >= 1.2)
    rate = 60 * 0.1 * np.sqrt(sample_rate_hz) * np.random.default_rng(3).standard_normal(n)
    path = tmp_path / "gap.csv"
    write_replay_log(path, t[keep], rate[keep], {}, {"sample_rate_hz": sample_rate_hz})
    return path


@pytest.mark.filterwarnings("error:RRD file has no footer")
@pytest.mark.parametrize("sig, name", [(signal.SIGTERM, "SIGTERM"), (signal.SIGHUP, "SIGHUP"),
                                       (signal.SIGINT, "Ctrl-C")])
def test_stop_signals_end_a_realtime_replay_cleanly(gap_log, tmp_path, process_groups, sig, name):
    out_rrd = tmp_path / "r.rrd"
    p = fogmon_process("replay", str(gap_log), "--realtime", "--rrd", str(out_rrd), "--window-s", "5.12",
                       "--no-progress")
    process_groups.append(p)
    line = ""
    while "gap:" not in line:                 # the replay is under way (recording time 1 s)
        line = p.stderr.readline()
        assert line or p.poll() is None, "replay ended before its first event"
    p.send_signal(sig)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 128 + sig and "Traceback" not in err, err
    assert f"fogmon: interrupted ({name})" in out and f"Wrote {out_rrd}" in out
    line = next(x for x in out.splitlines() if "samples at 50 Hz" in x)
    n, invalid = int(line.split()[0]), int(line.split("(")[1].split()[0])
    t, rate = read_scalars(str(out_rrd), "/rate/rate_dph")      # complete (a footer), every sample processed
    assert 50 <= n < 3000 and len(t) == n - invalid


def test_sigkill_of_a_serving_replay_frees_the_port(small_log, process_groups):
    """The --serve server dies with fogmon even on SIGKILL; the next --serve on the port works."""
    from helpers.net import free_port, listening, wait_until
    port = free_port()
    p = fogmon_process("replay", str(small_log[0]), "--serve", "--port", str(port), "--window-s", "40.96",
                       "--no-progress", "--quiet")
    process_groups.append(p)
    line = ""
    while "still serving" not in line:
        line = p.stderr.readline()
        assert line or p.poll() is None, "replay ended before serving"
    assert listening(port) == {"127.0.0.1"}
    p.kill()
    p.wait()
    wait_until(lambda: not listening(port), f"port {port} still taken after SIGKILL of fogmon")


def test_serve_on_a_busy_port_exits_2_with_one_line_and_leaves_nothing(small_log, tmp_path, capsys):
    from helpers.net import free_port
    port = free_port()
    out = tmp_path / "o.rrd"
    with socket.create_server(("127.0.0.1", port)):             # a stale server on the port
        assert main(["replay", str(small_log[0]), "--serve", "--port", str(port), "--rrd", str(out),
                     "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"fogmon replay: error: --serve: port {port} on 127.0.0.1 is already in use")
    assert len(err.strip().splitlines()) == 1 and not out.exists()


SIDECAR_OK = {"format": "fogmon capture v1", "kind": "serial", "protocol": "kvh-a", "sample_rate_hz": 200.0,
              "kvh_rot": "rate", "kvh_units": "deg", "axis": "z", "breaks": []}


@pytest.mark.parametrize("change, message", [
    ({"sample_rate_hz": "fast"}, "field sample_rate_hz: expected a number > 0, got 'fast'"),
    ({"protocol": "kvh-x"}, "field protocol: expected one of kvh-a, kvh-b, kvh-c, dsp3000, lines, got 'kvh-x'"),
    ({"breaks": [{"offset": -3, "missing_est": 1}]}, "field breaks: item 0: expected"),
    ({"breaks": {"offset": 3}}, "field breaks: expected a list"),
    ({"kind": None}, "field kind: missing"),
    ({"format": "something else"}, "not a fogmon capture sidecar"),
    ({"kvh_units": 3}, "field kvh_units: expected one of deg, rad, got 3"),
])
def test_a_malformed_sidecar_is_one_line_naming_file_and_field(tmp_path, capsys, change, message):
    from helpers.fake_device import stream

    cap = tmp_path / "raw-0001.bin"
    cap.write_bytes(stream(50)[0])
    side = {k: v for k, v in {**SIDECAR_OK, **change}.items() if v is not None}
    (tmp_path / "raw-0001.bin.json").write_text(json.dumps(side))
    for target in (cap, tmp_path):                               # the piece, and the archive folder
        assert main(["replay", str(target), "--no-progress", "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"fogmon replay: error: {cap}.json: ") and message in err, err
        assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("dbc", ["/etc/passwd", "../outside.dbc", "sub/../../outside.dbc", "link.dbc"])
def test_a_sidecar_cannot_name_a_file_outside_its_folder(tmp_path, capsys, dbc):
    arch = tmp_path / "arch"
    arch.mkdir()
    (tmp_path / "outside.dbc").write_text("root:x:0:0:secret\n")
    (arch / "link.dbc").symlink_to(tmp_path / "outside.dbc")
    (arch / "frames-0001.asc").write_text("date Mon Nov 23 10:00:00.000 am 2026\nbase hex  timestamps absolute\n")
    (arch / "frames-0001.asc.json").write_text(json.dumps({"format": "fogmon capture v1", "kind": "can",
                                                            "sample_rate_hz": 100.0, "dbc": dbc}))
    assert main(["replay", str(arch / "frames-0001.asc"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"fogmon replay: error: {arch}/frames-0001.asc.json: field dbc: ")
    assert len(err.strip().splitlines()) == 1 and "root:" not in err and "secret" not in err
