"""Other tools' recordings (ROS 1/2 bags and MCAP, PX4 ULog, MDF4, LAS), each written with
the format's own library (tests/helpers/recordings.py) and replayed: the same DADEV and whole-run ADEV as the equivalent
replay-log CSV (to 1e-12), gaps counted, units converted, and bad input a one-line error
naming the file and the field."""
from __future__ import annotations

import math
import re
import sys

import numpy as np
import pytest
from helpers.recordings import DPH_PER_RPS, write_imu_bag, write_las, write_mdf, write_ulog

from fogmon.block import Block
from fogmon.cli import build_parser, main
from fogmon.cli.pipeline_options import pipeline_config
from fogmon.cli.source_options import source_options
from fogmon.pipeline import run_pipeline
from fogmon.sinks.base import Sink
from fogmon.sources.open import open_replay_source
from fogmon.sources.options import SourceOptions

FS = 100.0
N = 6000


class Frames(Sink):
    """Keeps every DADEV row the pipeline emits, by axis ("" for a one-axis run)."""

    def __init__(self):
        self.adev = {}

    def frames(self, dadev, fit, t_end_s, axis=""):
        self.adev.setdefault(axis, []).append(dadev.adev_dph)


def replay_axes(path, *opts):
    """(Summary, {axis: DADEV rows}) of `fogmon replay PATH OPTS` through the real source
    and pipeline (axis "" for a one-axis run)."""
    argv = ["replay", str(path), "--window-s", "20.48", "--hop-s", "5.12", "--no-progress", *opts]
    args = build_parser(argv).parse_args(argv)
    sink = Frames()
    summary = run_pipeline(open_replay_source(args.recording, source_options(args)), pipeline_config(args), [sink])
    return summary, {a: np.vstack(rows) for a, rows in sink.adev.items()}


def replay(path, *opts):
    """(Summary, DADEV rows) of a one-axis `fogmon replay PATH OPTS`."""
    summary, adev = replay_axes(path, *opts)
    return summary, adev[""]


@pytest.fixture(scope="module")
def signal():
    """Rate (deg/h) of N samples at FS with samples 3000..3011 missing, and jittered stamps (s)."""
    rng = np.random.default_rng(17)
    rate_dph = 5.0 + 60 * 0.2 * math.sqrt(FS) * rng.standard_normal(N)
    keep = np.ones(N, bool)
    keep[3000:3012] = False
    t = np.arange(N) / FS + rng.uniform(-0.1, 0.1, N) / FS   # stamps jitter by 10 % of a period
    return t, rate_dph, keep


def csv_replay(folder, rate_dph, keep, t0_s=0.0):
    """Replay of the replay-log CSV holding ``rate_dph[keep]`` (deg/h, the values a reader
    gives after its unit conversion) on the grid from ``t0_s``: the equivalent CSV."""
    path = folder / "ref.csv"
    rows = np.column_stack([t0_s + (np.arange(N) / FS)[keep], rate_dph[keep]])
    np.savetxt(path, rows, fmt="%.17g", delimiter=",", comments="",   # every bit of the values
               header=f"# fogmon replay log v1\n# sample_rate_hz: {FS}\ntime_s,rate_dph")
    return replay(path)


def same_as_reference(got, reference, rtol=1e-12, present="samples"):
    """Same DADEV and whole-run ADEV as the CSV's replay, and the gap counted (``present``:
    the counter of samples read)."""
    (s, adev), (s_ref, adev_ref) = got, reference
    np.testing.assert_allclose(adev, adev_ref, rtol=rtol)
    np.testing.assert_allclose(s.overall.adev_dph, s_ref.overall.adev_dph, rtol=rtol)
    assert s.n_samples == s_ref.n_samples == N and s.sample_rate_hz == pytest.approx(FS, rel=1e-3)
    assert s.counters[present] == N - 12 and s.counters["samples_missing"] == 12 and s.counters["seq_gaps"] == 1


def one_line_error(argv, capsys, *parts):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for p in parts:
        assert p in err, err


# ------------------------------------------------------------------------------ ROS
@pytest.fixture(scope="module", params=["ros1", "ros2", "mcap"])
def bag(request, signal, tmp_path_factory):
    d = tmp_path_factory.mktemp(request.param)
    path = d / {"ros1": "run.bag", "ros2": "run_bag", "mcap": "run.mcap"}[request.param]
    if request.param == "mcap":   # a bare .mcap file: write a ROS 2 bag with MCAP storage, take its file
        write_imu_bag(d / "tmp_bag", *signal, "mcap")
        next((d / "tmp_bag").glob("*.mcap")).rename(path)
    else:
        write_imu_bag(path, *signal, request.param)
    return path


def test_ros_bags_and_mcap_replay_like_the_csv(bag, signal, tmp_path):
    t, rate, keep = signal
    got = replay(bag, "--topic", "/imu/data", "--axis", "z")
    same_as_reference(got, csv_replay(tmp_path, rate / DPH_PER_RPS * DPH_PER_RPS, keep))  # float64 rad/s in the bag
    assert "/imu/data angular_velocity.z" in got[0].source_name


def test_ros_axis_and_unit_conversion(bag, signal):
    t, rate, keep = signal
    src = open_replay_source(str(bag), source_options(build_parser(["replay", "x", "--axis", "x"]).parse_args(
        ["replay", str(bag), "--axis", "x"])))         # the only Imu topic is the default
    rec = src.to_recording()
    np.testing.assert_allclose(rec.rate_dph, 0.5 * rate[keep], rtol=1e-12)   # rad/s -> deg/h
    assert src.sample_rate_hz == pytest.approx(FS, rel=0.2 / N)   # stamps jitter +-0.1 period: the span fixes the rate
    np.testing.assert_allclose(rec.t_s, (np.arange(N) / FS)[keep], atol=0.1 / FS)


def test_ros_wrong_topic_is_one_line_naming_file_and_field(bag, capsys):
    one_line_error(["replay", str(bag), "--topic", "/imu/nope"], capsys, str(bag), "--topic:",
                   "'/imu/nope'", "/imu/data")
    one_line_error(["replay", str(bag), "--topic", "/temp"], capsys, "std_msgs/msg/Float64", "not sensor_msgs/msg/Imu")


# ------------------------------------------------------------------------------ ULog
def test_ulog_replays_like_the_csv_of_its_float32_values(signal, tmp_path):
    t, rate, keep = signal
    path = tmp_path / "flight.ulg"
    write_ulog(path, t, rate, keep)
    as_logged = np.float32(rate / DPH_PER_RPS).astype(np.float64) * DPH_PER_RPS   # ULog keeps float32 rad/s
    got = replay(path, "--axis", "z")
    same_as_reference(got, csv_replay(tmp_path, as_logged, keep, t0_s=10.0))
    assert "sensor_gyro:0 z" in got[0].source_name
    rec = open_replay_source(str(path), source_options(build_parser(["replay", "x"]).parse_args(
        ["replay", str(path)]))).to_recording()
    np.testing.assert_allclose(rec.aux["temp_c"], 35.0)
    assert rec.t_s[0] == pytest.approx(10.0 + t[0], abs=1e-6)   # timestamp_sample, s since boot


def test_ulog_wrong_topic_is_one_line(signal, tmp_path, capsys):
    path = tmp_path / "flight.ulg"
    write_ulog(path, *signal)
    one_line_error(["replay", str(path), "--topic", "sensor_gyro:2"], capsys, str(path), "--topic:",
                   "sensor_gyro:0")
    one_line_error(["replay", str(path), "--topic", "vehicle_status"], capsys, "not a gyro topic")


# ------------------------------------------------------------------------------ three axes
def whole_read(path, axis=None):
    """(source, all its blocks as one) of ``path`` read with ``--axis axis``."""
    src = open_replay_source(str(path), SourceOptions(axis=axis))
    return src, Block.concat(list(src.blocks()))


def equal_per_axis_to_one_axis_reads(path):
    """Without --axis a three-axis source x, y, z whose every axis is, block and recording,
    exactly the one-axis read of that axis (--axis a); --axis z,x a two-axis subset in that
    order. (source, whole read) of the three-axis read."""
    src, whole = whole_read(path)
    assert src.axes == whole.axes == ("x", "y", "z")
    rec = src.to_recording()
    assert rec.axes == ("x", "y", "z")
    for a in ("x", "y", "z"):
        one_src, one = whole_read(path, a)
        view = whole.axis(a)
        assert one_src.axes == one.axes == () and one_src.sample_rate_hz == src.sample_rate_hz
        for got, want in ((view.t_s, one.t_s), (view.rate_dph, one.rate_dph), (view.valid, one.valid)):
            np.testing.assert_array_equal(got, want)
        assert view.events == one.events and one_src.counters == src.counters
        one_rec = one_src.to_recording()
        np.testing.assert_array_equal(rec.for_axis(a).t_s, one_rec.t_s)
        np.testing.assert_array_equal(rec.for_axis(a).rate_dph, one_rec.rate_dph)
        for k, v in one_rec.aux.items():
            np.testing.assert_array_equal(rec.aux[k], v)
    pair_src, pair = whole_read(path, "z,x")
    assert pair_src.axes == pair.axes == ("z", "x")
    np.testing.assert_array_equal(pair.rate_dph, whole.rate_dph[:, [2, 0]])
    return src, whole


def test_ros_gives_three_axes_equal_to_the_one_axis_reads_and_the_accelerometer_in_g(bag, signal):
    t, rate, keep = signal
    src, whole = equal_per_axis_to_one_axis_reads(bag)
    np.testing.assert_allclose(src.to_recording().rate_dph, np.column_stack([0.5 * rate, -rate, rate])[keep],
                               rtol=1e-12)
    assert "/imu/data angular_velocity.x,y,z" in src.name
    assert sorted(whole.aux) == ["accel_x_g", "accel_y_g", "accel_z_g"]
    read = whole.valid.all(axis=1)
    assert np.count_nonzero(~read) == 12 and np.isnan(whole.aux["accel_z_g"][~read]).all()
    np.testing.assert_array_equal(whole.aux["accel_x_g"][read], 0.0)
    np.testing.assert_allclose(whole.aux["accel_z_g"][read], 9.81 / 9.80665, rtol=1e-15)   # m/s^2 / g0
    assert sorted(whole_read(bag, "z,x")[1].aux) == ["accel_x_g", "accel_z_g"]   # the axes picked
    assert whole_read(bag, "z")[1].aux == {}                                     # one axis: as always


def test_ulog_gives_three_axes_equal_to_the_one_axis_reads(signal, tmp_path):
    t, rate, keep = signal
    path = tmp_path / "flight.ulg"
    write_ulog(path, t, rate, keep)
    src, whole = equal_per_axis_to_one_axis_reads(path)
    as_logged = np.float32(np.column_stack([0.5 * rate, -rate, rate]) / DPH_PER_RPS).astype(np.float64)
    np.testing.assert_array_equal(src.to_recording().rate_dph, as_logged[keep] * DPH_PER_RPS)
    assert "sensor_gyro:0 x,y,z" in src.name and list(whole.aux) == ["temp_c"]


def test_replay_of_a_bag_without_axis_analyses_every_axis(bag, capsys):
    """`fogmon replay run.bag`: each axis's DADEV is the one-axis replay's of that axis; the
    console shows one column per axis."""
    summary, adev = replay_axes(bag)
    assert list(summary.axes) == list(adev) == ["x", "y", "z"]
    np.testing.assert_array_equal(adev["y"], replay(bag, "--axis", "y")[1])
    np.testing.assert_allclose(adev["y"], 2 * adev["x"], rtol=1e-12)              # y = -2 x, sample by sample
    assert main(["replay", str(bag), "--window-s", "20.48", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "invalid/lost samples per axis: x 12, y 12, z 12" in out
    assert re.search(r"^ +tau_s +x +y +z$", out, re.M) and re.search(r"^  coefficient unit +x +y +z$", out, re.M)


def test_imu_axis_that_is_not_x_y_z_is_one_line(bag, capsys):
    one_line_error(["replay", str(bag), "--axis", "x,w"], capsys, str(bag), "--axis x,w", "x, y and z")


def test_updown_of_three_axis_ulogs_needs_the_axis(signal, tmp_path, capsys):
    """z reads Earth's vertical rate at 45 deg (15.041 deg/h x sin 45 deg) x (1 + 1000 ppm)
    + 0.5 deg/h, up and then down: `fogmon updown --axis z` finds both."""
    t, _, keep = signal
    earth_dph = 15.041067 * math.sin(math.radians(45.0)) * 1.001
    up, down = tmp_path / "up.ulg", tmp_path / "down.ulg"
    write_ulog(up, t, np.full(N, 0.5 + earth_dph), keep)
    write_ulog(down, t, np.full(N, 0.5 - earth_dph), keep)
    argv = ["updown", "--up", str(up), "--down", str(down), "--lat-deg", "45"]
    one_line_error(argv, capsys, str(up), "has axes x, y, z", "give --axis NAME")
    assert main([*argv, "--axis", "z"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"bias +\+0\.500", out) and re.search(r"scale-factor error \+1000\.\d ", out), out


# ------------------------------------------------------------------------------ MDF4
def test_mdf4_channel_replays_like_the_csv(signal, tmp_path):
    t, rate, keep = signal
    path = tmp_path / "bench.mf4"
    write_mdf(path, *signal)
    s, adev = replay(path, "--channel", "GyroZ")
    same_as_reference((s, adev), csv_replay(tmp_path, rate / 3600.0 * 3600.0, keep, t0_s=10.0))  # deg/s in the file
    assert "GyroZ (deg/s)" in s.source_name


def test_mdf4_missing_channel_and_unit(signal, tmp_path, capsys):
    path = tmp_path / "bench.mf4"
    write_mdf(path, *signal)
    one_line_error(["replay", str(path), "--channel", "GyroX"], capsys, str(path), "--channel:", "'GyroX'",
                   "GyroZ")
    one_line_error(["replay", str(path)], capsys, "needs --channel NAME", "GyroZ, Temp")
    one_line_error(["replay", str(path), "--channel", "Temp"], capsys, "channel Temp", "'degC'", "--rate-unit")


# ------------------------------------------------------------------------------ LAS
def test_las_time_indexed_replays_like_the_csv(signal, tmp_path):
    import lasio
    t, rate, keep = signal
    path = tmp_path / "tool.las"
    write_las(path, *signal)
    got = replay(path)
    as_written = np.full(N, np.nan)
    as_written[keep] = lasio.read(str(path))["GYRO"]                # the decimal text the file holds
    same_as_reference(got, csv_replay(tmp_path, as_written, keep))
    assert "curve GYRO (DEG/HR) over TIME" in got[0].source_name


def test_las_depth_indexed_needs_a_time_curve(signal, tmp_path, capsys):
    path = tmp_path / "tool.las"
    write_las(path, *signal, depth_index=True)
    one_line_error(["replay", str(path)], capsys, str(path), "depth-indexed", "--time-channel")
    one_line_error(["replay", str(path), "--time-channel", "TIME", "--channel", "ROT"], capsys,
                   "--channel:", "'ROT'", "GYRO (DEG/HR)")
    src = open_replay_source(str(path), source_options(build_parser(["replay", "x"]).parse_args(
        ["replay", str(path), "--time-channel", "TIME"])))
    rec = src.to_recording()
    np.testing.assert_allclose(rec.aux["depth_m"][:3], [1000.0, 1000.01, 1000.02])


def test_a_missing_extra_names_it(tmp_path, capsys, monkeypatch):
    path = tmp_path / "tool.las"
    path.write_text("~V\n")
    monkeypatch.setitem(sys.modules, "lasio", None)   # as if not installed: importing it raises ImportError
    one_line_error(["replay", str(path)], capsys, str(path), "needs lasio", "pip install 'fogmon[las]'")


def test_mdf4_can_bus_logging_with_a_dbc_replays_like_the_csv(signal, tmp_path):
    """Raw CAN frames in an MDF4 bus log (python-can's MF4 writer, asammdf underneath),
    decoded with the example DBC: the rate signal is 1e-6 deg/s per bit."""
    from importlib.resources import files

    import can
    import cantools
    dbc = str(files("fogmon") / "data" / "gyro_example.dbc")
    db = cantools.database.load_file(dbc)
    msg = db.get_message_by_name("GYRO_RATE")
    t, rate, keep = signal
    path = tmp_path / "bus.mf4"
    values = np.full(N, np.nan)
    with can.Logger(str(path)) as log:
        for i in np.flatnonzero(keep):
            data = msg.encode({"rate": round(float(rate[i]) / 3600.0, 6), "temperature": 25.0, "counter": int(i % 16),
                               "valid": 1})
            values[i] = db.decode_message(msg.frame_id, data)["rate"] * 3600.0   # what the decoder gives, deg/h
            log.on_message_received(can.Message(timestamp=1000.0 + i / FS, arbitration_id=msg.frame_id, data=data,
                                                is_extended_id=False))
    s, adev = replay(path, "--dbc", dbc)
    same_as_reference((s, adev), csv_replay(tmp_path, values, keep), present="frames_ok")


def test_explain_reads_a_bag_like_its_csv(bag, tmp_path):
    """The batch path (explain) gets the same Recording from a reader as from the replay log."""
    from fogmon.cli.source_options import source_options
    from fogmon.formats.replay_log import read_replay_log
    from fogmon.sources.open import read_recording
    rec = read_recording(str(bag), source_options(build_parser(["explain", "x", "--report", "r"]).parse_args(
        ["explain", str(bag), "--report", "r.json", "--axis", "y"])))
    ref = read_replay_log(csv_replay_file(tmp_path, rec.rate_dph, rec.t_s, rec.sample_rate_hz))
    np.testing.assert_array_equal(rec.rate_dph, ref.rate_dph)
    np.testing.assert_array_equal(rec.grid_index(), ref.grid_index())
    assert len(rec) == N - 12 and rec.sample_rate_hz == pytest.approx(FS, rel=0.2 / N)


def csv_replay_file(folder, rate_dph, t_s, sample_rate_hz):
    path = folder / "same.csv"
    np.savetxt(path, np.column_stack([t_s, rate_dph]), fmt="%.17g", delimiter=",", comments="",
               header=f"# fogmon replay log v1\n# sample_rate_hz: {sample_rate_hz!r}\ntime_s,rate_dph")
    return path


def test_explain_end_to_end_on_a_ulog(signal, tmp_path, capsys):
    path = tmp_path / "flight.ulg"
    write_ulog(path, *signal)
    report = tmp_path / "r.json"
    assert main(["explain", str(path), "--topic", "sensor_gyro", "--axis", "z", "--report", str(report),
                 "--bootstrap", "8", "--max-effects", "0", "--quiet"]) == 0
    import json
    assert json.loads(report.read_text())["recording"] == str(path)


def test_las_nulls_and_implausible_rates_are_counted_invalid_samples(signal, tmp_path):
    t, rate, keep = signal
    r = rate.copy()
    r[100] = -9999.25         # the NULL value of the file's ~Well section (lasio's default): no sample
    r[200] = 1e12             # beyond any gyro (the plausibility gate)
    path = tmp_path / "tool.las"
    write_las(path, t, r, keep)
    s, _ = replay(path)
    assert s.counters["null_samples"] == 1 and s.counters["implausible_samples"] == 1
    assert s.n_invalid == 12 + 2 and s.counters["samples"] == N - 12


def test_ros_fast_layout_reads_what_full_deserialization_reads(bag, monkeypatch):
    """Messages read by field offsets (verified on one message per length) equal the
    messages deserialized one by one by rosbags."""
    from fogmon.sources.files import rosbag
    from fogmon.sources.options import SourceOptions
    opts = SourceOptions(axis="y", max_rate_dph=1e12)
    fast = rosbag.open_source(str(bag), opts).to_recording()
    monkeypatch.setattr(rosbag, "_verified_layout", lambda *a: None)
    slow = rosbag.open_source(str(bag), opts).to_recording()
    np.testing.assert_array_equal(fast.rate_dph, slow.rate_dph)
    np.testing.assert_array_equal(fast.t_s, slow.t_s)


def test_thermal_and_inorbit_read_other_formats(signal, tmp_path, capsys):
    """A LAS file's deg C curve is temp_c: `fogmon thermal` calibrates from it; `fogmon
    inorbit` reads the same file."""
    t, rate, keep = signal
    import lasio
    las = lasio.LASFile()
    las.append_curve("TIME", t[keep], unit="S")
    las.append_curve("GYRO", rate[keep] + 0.5 * (20 + t[keep] / 6), unit="DEG/HR")   # drifts with temperature
    las.append_curve("TEMP", 20 + t[keep] / 6, unit="DEGC")
    path = tmp_path / "tool.las"
    las.write(str(path), version=2.0)
    assert main(["thermal", str(path), "--average-s", "5"]) == 0
    assert f"{N - 12} samples, T 20.0..30.0 deg C" in capsys.readouterr().out     # temp_c from the DEGC curve
    assert main(["inorbit", str(path), "--period-s", "10"]) == 0


def test_sim_like_takes_the_time_base_of_a_ulog(signal, tmp_path, capsys):
    path = tmp_path / "flight.ulg"
    write_ulog(path, *signal)
    model = tmp_path / "m.toml"
    model.write_text("[sensor]\nsample_rate_hz = 100.0\n\n[noise]\nQ_arcsec = 0.0\nN_dpsh = 0.1\nB_dph = 0.0\n"
                     "K_dphsh = 0.0\nR_dphh = 0.0\n")
    out = tmp_path / "sim.csv"
    assert main(["sim", "--model", str(model), "--like", str(path), "--out", str(out), "--seed", "1"]) == 0
    from fogmon.formats.replay_log import read_replay_log
    sim = read_replay_log(out)
    assert len(sim) == N - 12 and "temp_c" in sim.aux       # the ULog's samples, gap and temperature
