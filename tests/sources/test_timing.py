"""The sample grid from time stamps (fogmon/sources/files/timing.py, docs/readers.md "What
every reader does with time") on the stamp patterns of real loggers that an outside check
found read wrong (2026-12-01): a wandering clock, an IMU whose integration intervals vary
and whose logger drops samples, a slow topic with an early first sample, and a replay log
whose jittered steps have a median away from their mean."""
from __future__ import annotations

import os

import numpy as np
import pytest

from fogmon.cli import main
from fogmon.sources.files.stamped import irregular_message
from fogmon.sources.files.timing import grid_index


def test_a_clock_whose_local_rate_wanders_is_refused_with_the_resampling():
    rng = np.random.default_rng(1)
    n = 2000
    local = 1.0 + 0.045 * np.sin(np.arange(n) / 300.0)          # the local rate 4.5 % off, no sample lost
    t = np.cumsum(local / 69.2) + rng.uniform(0, 2e-4, n)
    _, timing = grid_index(t, "razor.bag topic /imu", "header.stamp")
    assert timing.irregular and timing.drifting and timing.missing == 0
    msg = irregular_message(timing, "razor.bag topic /imu")
    assert "no uniform grid holds the samples" in msg and "resample_hz" in msg


def test_dropped_samples_under_jittered_integration_intervals_are_not_read_as_a_slower_grid():
    rng = np.random.default_rng(2)
    step = rng.uniform(4.3e-3, 5.1e-3, 1900)                      # an IMU's integration intervals
    keep = np.ones(1901, bool)
    keep[rng.choice(np.arange(1, 1900), 110, replace=False)] = False   # the logger drops 5.8 %
    keep[1:80:2] = False                                           # every other one at the start
    t = np.concatenate(([0.0], np.cumsum(step)))[keep]
    _, timing = grid_index(t, "flight.ulg topic sensor_combined:0", "timestamp")
    assert timing.irregular                                        # was 1 grid at the mean rate, no gap


def test_a_slow_topic_with_an_early_first_sample_keeps_its_rate():
    t = 3.2655 + np.array([0.0, 0.0014, 1.0033, 2.0007, 3.0025, 4.0044, 5.0003, 6.0023, 7.0010, 8.0029])
    _, timing = grid_index(t, "flight.ulg topic sensor_gyro:1", "timestamp_sample")
    assert timing.rate_hz == pytest.approx(1.0, abs=2e-3)         # was 1.0576 Hz


def test_a_regular_logger_with_delays_and_gaps_is_not_irregular():
    rng = np.random.default_rng(3)
    k = np.arange(20000)
    k = k[rng.random(len(k)) > 0.01]                               # 1 % lost
    t = k / 100.0 + np.minimum(rng.exponential(1e-3, len(k)), 8e-3)   # delays of a few ms
    _, timing = grid_index(t, "can.log message imu", "timestamp")
    assert not timing.irregular and timing.rate_hz == pytest.approx(100.0, rel=1e-4)
    assert abs(timing.missing - (20000 - len(k))) <= 3


@pytest.mark.parametrize("stated", [None, "90.909"])
def test_a_replay_log_whose_steps_have_a_skewed_median_reads_at_its_rate(stated, tmp_path, capsys):
    rng = np.random.default_rng(4)
    n = 3000
    step = np.where(np.arange(1, n) % 20 == 0, 13.28e-3, 10.88e-3)     # a clock corrected every 20 samples
    t = np.concatenate(([0.0], np.cumsum(step))) + rng.uniform(0, 1e-5, n)
    assert abs(np.median(np.diff(t)) / 0.011 - 1) > 0.01                # the median step 1.1 % short
    path = tmp_path / "launch.csv"
    head = "# fogmon replay log v1\n" + (f"# sample_rate_hz: {stated}\n" if stated else "")
    rows = "\n".join(f"{a:.8f},{b:.3f}" for a, b in zip(t, rng.normal(0, 400, n), strict=True))
    path.write_text(head + "time_s,rate_dph\n" + rows + "\n")
    assert main(["replay", str(path), "--rrd", str(tmp_path / "o.rrd"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "3000 samples at 90.909" in out and "(0 invalid/lost)" in out


def test_reader_options_that_do_not_apply_to_a_replay_log_are_an_error(capsys):
    """An outside check (2026-12-01): `--time-channel`, `--channel` (and `--topic`, `--dbc`,
    `--protocol`, `--rate-hz`) on a replay log were accepted and ignored."""
    log = os.path.join(os.path.dirname(__file__), "..", "..", "replay_logs", "sim_in_orbit_1hz.csv")
    for extra, flag in ((["--time-channel", "T"], "--time-channel"), (["--rate-hz", "2"], "--rate-hz"),
                        (["--topic", "/imu", "--protocol", "kvh-a"], "--protocol, --topic")):
        assert main(["replay", log, *extra, "--duration-s", "10", "--no-progress", "--quiet"]) == 2
        err = capsys.readouterr().err
        assert f"a replay log (time_s and rate columns in deg/h, its own sample_rate_hz; docs/formats.md): {flag} " \
               f"do" in err and len(err.strip().splitlines()) == 1
