"""Options of `fogmon replay` / `fogmon monitor` and the tau grids: every wrong value is
a one-line error (exit 2) before the run, taus that cannot be computed are named in a
warning, a silent device exits 1 with one line, a run shorter than one window says why."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
import uuid

import numpy as np
import pytest
from helpers import REPO
from helpers.doubles import archive_in

from fogmon.cli import command_flags, main
from fogmon.davar.batch import dadev, oadev
from fogmon.davar.streaming import StreamingDadev
from fogmon.davar.taus import MAX_PER_DECADE, tau_grid
from fogmon.errors import FogmonError, FogmonWarning
from fogmon.formats.replay_log import write_replay_log
from fogmon.sinks.base import Summary
from fogmon.sinks.console import format_summary

ROOT = REPO
DBC = str(ROOT / "fogmon" / "data" / "gyro_example.dbc")


@pytest.fixture
def log(tmp_path):
    """12,000 samples at 50 Hz (240 s) of white rate noise."""
    sample_rate_hz, n = 50.0, 12_000
    t = np.arange(n) / sample_rate_hz
    path = tmp_path / "run.csv"
    write_replay_log(path, t, 2.0 + np.random.default_rng(5).standard_normal(n), {}, {"sample_rate_hz": sample_rate_hz})
    return path


# ------------------------------------------------------------------ tau grids (API)
def test_api_names_the_taus_it_cannot_compute():
    y = np.random.default_rng(1).standard_normal(10_000)           # 100 s at 100 Hz: n/4 = 25 s
    with pytest.warns(FogmonWarning, match=r"taus 2621\.44, 5000 s left out: .* 0\.01 \.\. 25 s \(n = 10000"):
        res = oadev(y, 100.0, taus=[0.02, 2621.44, 5000])
    assert res.tau_s.tolist() == [0.02]
    with pytest.warns(FogmonWarning, match=r"tau 0\.001 s left out"):            # shorter than half a sample
        assert tau_grid(100.0, 1000, [0.001, 0.1]).tolist() == [10]
    with pytest.warns(FogmonWarning, match=r"tau 20 s left out: .* 0\.01 \.\. 10 s \(n = 4000 samples"):
        StreamingDadev(100.0, 40.0, taus=[1.0, 20.0])               # window 4000 samples
    with pytest.warns(FogmonWarning, match=r"tau 20 s left out"):
        dadev(y, 100.0, 40.0, taus=[1.0, 20.0])
    with pytest.raises(FogmonError, match=r"requested taus 30, 40 s: none can be computed"):
        oadev(y, 100.0, taus=[30.0, 40.0])


def test_api_grids_by_name_or_per_decade_drop_nothing_silently(recwarn):
    assert tau_grid(1.0, 4000, 4).tolist() == [1, 2, 3, 6, 10, 18, 32, 56, 100, 178, 316, 562, 1000]
    assert len(tau_grid(1.0, 4000, MAX_PER_DECADE)) > 0 and tau_grid(1.0, 400, "octave").tolist()[-1] == 64
    assert not recwarn.list
    with pytest.raises(FogmonError, match=r"taus 1000: an integer is a number of taus per decade, 1\.\.32; "
                                          r"for one tau of 1000 s give it as 1000\.0"):
        tau_grid(1.0, 100_000, 1000)
    with pytest.raises(FogmonError, match="per decade"):
        tau_grid(1.0, 100_000, 0)


# ------------------------------------------------------------------ replay options
@pytest.mark.parametrize("argv, message", [
    (["--taus", "1000"], "argument --taus: taus 1000: an integer is a number of taus per decade, 1..32; "
                         "for one tau of 1000 s give it as 1000.0"),
    (["--taus", "0"], "argument --taus: taus 0: an integer is a number of taus per decade"),
    (["--taus", "1,nan"], "argument --taus: tau values must be finite and > 0 s"),
    (["--port", "0"], "argument --port: must be an integer in 1..65535, got '0'"),
    (["--port", "70000"], "argument --port: must be an integer in 1..65535"),
    (["--window-s", "inf"], "argument --window-s: must be a finite number > 0, got 'inf'"),
    (["--hop-s", "nan"], "argument --hop-s: must be a finite number > 0"),
    (["--duration-s", "-1"], "argument --duration-s: must be a finite number > 0"),
    (["--realtime", "0"], "argument --realtime: must be a finite number > 0"),
    (["--rate-hz", "1e12"], "argument --rate-hz: must be a finite number > 0 and <= 1e+06, got '1e12'"),
])
def test_replay_bad_option_values_are_usage_errors(log, capsys, argv, message):
    with pytest.raises(SystemExit) as e:
        main(["replay", str(log), *argv])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"fogmon replay: error: {message}") and err.endswith(" (see fogmon replay --help)\n")
    assert err.count("\n") == 1


@pytest.mark.parametrize("argv, message", [
    (["--taus", "500.0"], "requested tau 500 s: cannot be computed: an Allan deviation needs tau from one sample "
                          "to n/4 samples, 0.02 .. 10.24 s (n = 2048 samples at 50 Hz, tau rounded to whole samples)"),
    (["--window-s", "20", "--hop-s", "30"], "--hop-s 30 s is longer than the window (20 s): the samples between "
                                            "windows would never be analysed"),
    (["--window-s", "1000"], "--window-s 1000 s is longer than the recording (240 s = 12000 samples)"),
    (["--duration-s", "60", "--window-s", "100"], "--window-s 100 s is longer than the --duration-s run "
                                                  "(60 s = 3000 samples)"),
    (["--duration-s", "0.001"], "--duration-s 0.001 s is shorter than one sample at 50 Hz"),
    (["--duration-s", "0.1"], "--duration-s leaves 5 samples at 50 Hz: an Allan deviation needs at least 8"),
    (["--window-s", "0.1"], "--window-s 0.1 s holds fewer than 8 samples at 50 Hz"),
])
def test_replay_option_values_that_cannot_work_are_one_line_errors(log, capsys, argv, message):
    assert main(["replay", str(log), "--no-progress", *argv]) == 2
    err = capsys.readouterr().err
    assert err == f"fogmon replay: error: {message}\n"


def test_replay_names_the_taus_it_leaves_out_once(log, capsys):
    assert main(["replay", str(log), "--no-progress", "--taus", "0.1,1,50.0"]) == 0
    cap = capsys.readouterr()
    # the window (2048 samples) cannot hold 50 s, the whole run (12000 samples, n/4 = 60 s) can
    assert cap.err == ("fogmon replay: warning: tau 50 s left out: an Allan deviation needs tau from one sample to "
                       "n/4 samples, 0.02 .. 10.24 s (n = 2048 samples at 50 Hz, tau rounded to whole samples)\n")
    rows = [ln.split() for ln in cap.out.splitlines()
            if ln.strip() and ln.strip()[0].isdigit() and len(ln.split()) == 6]
    assert [float(r[0]) for r in rows] == [0.1, 1.0, 50.0]


def test_replay_default_window_fits_duration(log, capsys):
    assert main(["replay", str(log), "--no-progress", "--duration-s", "100"]) == 0
    # 5000 samples: a quarter is 1250 -> 1024 samples = 20.48 s, hop window / 8
    assert "DADEV windows of 20.48 s every 2.56 s" in capsys.readouterr().out


# ------------------------------------------------------------------ live runs
def test_silent_can_bus_exits_1_with_one_line_and_leaves_nothing(tmp_path, capsys):
    ch = f"silent-{uuid.uuid4().hex}"
    rc = main(["monitor", "--can", ch, "--interface", "virtual", "--dbc", DBC, "--duration-s", "1",
               "--archive", str(tmp_path), "--no-progress"])
    cap = capsys.readouterr()
    assert rc == 1 and cap.out == ""
    line = cap.err.strip()
    assert len(cap.err.splitlines()) == 1
    assert line.startswith(f"fogmon monitor: nothing was received from CAN GYRO_RATE.rate (deg/s), 100 Hz on "
                           f"virtual:{ch} in ") and line.endswith(" s; no archive written")
    assert not list(tmp_path.iterdir())


def test_can_bus_with_only_foreign_frames_exits_1_naming_what_arrived(tmp_path, capsys):
    import threading

    import can

    ch = f"foreign-{uuid.uuid4().hex}"
    stop = threading.Event()

    def send():  # frames the DBC does not describe, until the monitor has finished
        with can.Bus(interface="virtual", channel=ch) as bus:
            while not stop.is_set():
                bus.send(can.Message(arbitration_id=0x7FF, data=bytes(8), is_extended_id=False))
                stop.wait(0.01)

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        rc = main(["monitor", "--can", ch, "--interface", "virtual", "--dbc", DBC, "--duration-s", "1",
                   "--archive", str(tmp_path), "--no-progress"])
    finally:
        stop.set()
        sender.join(10)
    arch = archive_in(tmp_path)
    cap = capsys.readouterr()
    assert rc == 1 and cap.out == "" and len(cap.err.splitlines()) == 1
    assert re.fullmatch(rf"fogmon monitor: no sample decoded from CAN GYRO_RATE\.rate \(deg/s\), 100 Hz on "
                        rf"virtual:{ch} in [\d.]+ s although [\d,]+ CAN frames arrived \(other_frames [\d,]+\): check "
                        rf"--protocol/--baud or --dbc/--can-message; the raw input is in {arch}\n", cap.err), cap.err
    assert os.path.getsize(os.path.join(arch, "frames-0001.asc")) > 0


def test_run_shorter_than_the_window_says_why():
    s = Summary("KVH", 100.0, 655.36, 81.92, n_samples=12_000, t_first_s=0.0, t_last_s=119.99)
    text = format_summary(s, command_flags("replay"))
    assert ("  0 DADEV windows of 655.36 s every 81.92 s\n  no DADEV window: the window is 65536 samples = 655.36 s "
            "at 100 Hz and the run had 12,000 samples (120 s); use --window-s 20.48 (or any window up to 120 s)"
            ) in text


@pytest.mark.timeout(1200)
def test_live_run_stopped_before_one_window_says_why(fake_kvh, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.Popen([sys.executable, "-m", "fogmon", "monitor", "--serial", fake_kvh, "--protocol", "kvh-a",
                          "--axis", "z", "--archive", str(tmp_path), "--window-s", "600", "--no-progress"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)

    def csv() -> str:
        return os.path.join(archive_in(tmp_path), "samples-0001.csv")

    try:
        deadline = time.monotonic() + 600  # failure guard only (a cold numba compile under load): we wait for data
        while not os.path.exists(csv()) or os.path.getsize(csv()) < 20_000:
            assert time.monotonic() < deadline and p.poll() is None, p.stderr.read() if p.poll() is not None else ""
            time.sleep(0.1)
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    n = int(next(ln for ln in out.splitlines() if "samples at 1000 Hz" in ln).split()[0])
    assert "  0 DADEV windows of 600 s every 75 s" in out, err
    assert (f"  no DADEV window: the window is 600000 samples = 600 s at 1000 Hz and the run had {n:,} samples "
            f"({n / 1000:g} s); use --window-s ") in out


@pytest.mark.parametrize("argv, message", [
    (["--can", "can0", "--dbc", "fogmon/data/gyro_example.dbc", "--can-bitrate", "-1"],
     "argument --can-bitrate: must be an integer in 1000..8,000,000, got '-1'"),
    (["--serial", "/dev/null", "--baud", "0"], "argument --baud: must be an integer in 1..50,000,000, got '0'"),
    (["--serial", "/dev/null", "--protocol", "lines", "--rate-hz", "0"],
     "argument --rate-hz: must be a finite number > 0"),
])
def test_monitor_bad_port_values_are_usage_errors(capsys, argv, message):
    with pytest.raises(SystemExit) as e:
        main(["monitor", *argv])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"fogmon monitor: error: {message}") and err.endswith(" (see fogmon monitor --help)\n")
    assert err.count("\n") == 1


@pytest.mark.parametrize("value", ["0", "1", "1.5", "-0.2", "nan"])
def test_fit_confidence_range_is_one_message_for_both_ends(capsys, value):
    """0 and 1 are refused alike, by the rule that says what is accepted (0 < p < 1)."""
    with pytest.raises(SystemExit) as e:
        main(["fit", "curve.csv", "--confidence", value])
    assert e.value.code == 2
    assert capsys.readouterr().err == (f"fogmon fit: error: argument --confidence: must be a finite number > 0 and "
                                       f"< 1, got '{value}' (see fogmon fit --help)\n")


def test_number_open_at_both_ends():
    import argparse

    from fogmon.cli.values import number
    p = number(0, 1, above=True, below=True)
    assert p("0.5") == 0.5 and p("1e-9") == 1e-9
    for bad in ("0", "1"):
        with pytest.raises(argparse.ArgumentTypeError, match="> 0 and < 1"):
            p(bad)
    assert number(0, 1)("1") == 1.0 and number(0, 1, below=True)("0") == 0.0   # closed ends stay closed
