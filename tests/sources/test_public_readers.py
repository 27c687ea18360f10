"""The readers on public files as users have them (tests/data/public, PROVENANCE.md): each
compared with the format's own library (values, time stamps) and the Allan deviation
with allantools.oadev on the same data; the time from the stamps (issue 30)."""
from __future__ import annotations

import math
import os
import warnings

import allantools
import can
import cantools
import numpy as np
import pytest

import fogmon
from fogmon.errors import FogmonError, FogmonWarning
from fogmon.sources.files.stamped import DPH_PER_RPS
from fogmon.sources.open import file_info, open_replay_source, read_recording
from fogmon.sources.options import SourceOptions

PUBLIC = os.path.join(os.path.dirname(__file__), "..", "data", "public")
CAN_DIR = os.path.join(PUBLIC, "can")
DBC = os.path.join(CAN_DIR, "canmod-gps.dbc")
DBC_20MS = os.path.join(CAN_DIR, "canmod-gps_cycle20ms.dbc")


def pub(*parts: str) -> str:
    return os.path.join(PUBLIC, *parts)


def same_adev(rec) -> None:
    """fogmon's ADEV of a gap-free recording equals allantools.oadev on the same values."""
    res = fogmon.oadev(rec.rate_dph, rec.sample_rate_hz, taus="octave", exclude_motion=False)
    ok = np.isfinite(res.adev_dph)
    taus, dev, _, _ = allantools.oadev(rec.rate_dph, rate=rec.sample_rate_hz, data_type="freq",
                                       taus=res.tau_s[ok])
    np.testing.assert_allclose(taus, res.tau_s[ok], rtol=1e-12)
    np.testing.assert_allclose(dev, res.adev_dph[ok], rtol=1e-9)


def test_ulog_without_sensor_gyro_reads_sensor_combined_at_its_stamped_rate():
    import pyulog
    path = pub("ulog", "sample_bench_8s.ulg")
    src = open_replay_source(path, SourceOptions(axis="z"))
    assert "sensor_combined:0" in src.name and "most samples" in src.name
    assert src.sample_rate_hz == pytest.approx(248.52, abs=0.02)       # not 250: the IMU runs at 248.5 Hz
    rec = src.to_recording()
    d = pyulog.ULog(path, ["sensor_combined"]).data_list[0].data
    np.testing.assert_array_equal(rec.rate_dph, d["gyro_rad[2]"].astype(np.float64) * DPH_PER_RPS)
    t = d["timestamp"] * 1e-6
    assert len(rec) == len(t) == src.n_samples                          # no gap: every step one period
    assert np.max(np.abs(rec.t_s - t)) < 0.5 / src.sample_rate_hz       # the grid within half a period of the stamps
    same_adev(rec)


def test_ulog_decimated_topic_is_a_warning_and_the_default_is_the_fullest():
    path = pub("ulog", "cubeorange_gyro_1hz.ulg")
    assert "sensor_combined:0" in open_replay_source(path, SourceOptions(axis="z")).name
    with pytest.warns(FogmonWarning, match="sensor_gyro:1 is decimated"):
        src = open_replay_source(path, SourceOptions(axis="z", topic="sensor_gyro:1"))
    assert src.sample_rate_hz == pytest.approx(1.0, rel=1e-3)


def test_alternating_steps_are_refused_with_the_resampling_that_fixes_them():
    path = pub("ulog", "sitl_alternating_steps.ulg")
    with pytest.raises(FogmonError, match=r"188\.243 Hz mean.*resample_hz.*e\.g\. 83\.3"):
        open_replay_source(path, SourceOptions(axis="z"))
    src = open_replay_source(path, SourceOptions(axis="z", resample_hz=125.0))
    assert src.sample_rate_hz == 125.0          # blocks of 8 ms: the 8 ms steps leave some without a sample
    import pyulog
    d = pyulog.ULog(path, ["sensor_combined"]).data_list[0].data
    t = d["timestamp"] * 1e-6
    v = d["gyro_rad[2]"].astype(np.float64) * DPH_PER_RPS
    block = np.floor((t - t[0]) * 125.0).astype(int)
    want = {b: v[block == b].mean() for b in np.unique(block)}       # block means, computed here
    rec = src.to_recording()
    got = dict(zip(np.rint((rec.t_s - t[0]) * 125.0).astype(int).tolist(), rec.rate_dph, strict=True))
    assert got.keys() == want.keys()
    np.testing.assert_allclose([got[b] for b in want], list(want.values()), rtol=1e-12)
    assert len(rec) / (rec.grid_index()[-1] + 1) > 0.9
    hint = read_recording(path, SourceOptions(axis="z", resample_hz=250 / 3)).to_block()
    assert hint.valid.all()                                            # the rate the error suggests: no gap
    same_adev(read_recording(path, SourceOptions(axis="z", resample_hz=250 / 3)))


def test_ros1_bag_matches_rosbags_and_allantools():
    from pathlib import Path

    from rosbags.highlevel import AnyReader
    path = pub("ros1", "jackal_imu_50hz_20s.bag")
    rec = read_recording(path, SourceOptions(axis="z"))
    with AnyReader([Path(path)]) as r:
        conns = [c for c in r.connections if c.topic == "/imu/data"]
        msgs = [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages(connections=conns)]
    ns = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in msgs])
    np.testing.assert_array_equal(rec.rate_dph, [m.angular_velocity.z * DPH_PER_RPS for m in msgs])
    np.testing.assert_allclose(rec.t_s, (ns - ns[0]) * 1e-9, atol=1e-9)
    assert rec.sample_rate_hz == pytest.approx(50.0, rel=1e-9)
    same_adev(rec)


def test_mcap_with_a_schema_rosbags_cannot_parse_lists_its_topics_with_types():
    path = pub("ros2", "topics_and_services.mcap")
    with pytest.raises(FogmonError) as e:
        open_replay_source(path)
    assert "no sensor_msgs/msg/Imu topics" in str(e.value)
    assert "/add_two_ints/_service_event (example_interfaces/srv/AddTwoInts_Event, 6)" in str(e.value)
    entries = {x.name: x for x in file_info(path)}
    assert entries["/parameter_events"].count == 7 and entries["/rosout"].type == "rcl_interfaces/msg/Log"


def _cantools_decoded(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Time stamps (s) and AngularRateZ (deg/s) of every gnss_imu frame, decoded here."""
    db = cantools.database.load_file(DBC)
    msg = db.get_message_by_name("gnss_imu")
    t, z = [], []
    for m in can.LogReader(path):
        if m.arbitration_id == msg.frame_id and not m.is_error_frame:
            t.append(m.timestamp)
            z.append(msg.decode(bytes(m.data))["AngularRateZ"])
    return np.array(t), np.array(z, dtype=np.float64)


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".trc", ".log", ".csv", ".mf4"])
def test_can_logs_take_the_rate_from_their_stamps(suffix):
    path = os.path.join(CAN_DIR, "canmod_imu_8s" + suffix)
    opts = SourceOptions(dbc=DBC, can_rate="AngularRateZ")      # the DBC has no cycle time: no --rate-hz needed
    src = open_replay_source(path, opts)
    rec = src.to_recording()
    t, z = _cantools_decoded(path)
    assert src.sample_rate_hz == pytest.approx(99.907, abs=0.001) and len(rec) == len(t) == 800
    np.testing.assert_allclose(rec.rate_dph, z * 3600.0, rtol=1e-12)
    assert np.max(np.abs(rec.t_s - (t - t[0]))) < 1.0 / src.sample_rate_hz     # steps 4.35-17.85 ms
    same_adev(rec)


def test_a_dbc_cycle_time_or_rate_that_contradicts_the_stamps_is_refused_unless_forced():
    path = os.path.join(CAN_DIR, "canmod_imu_8s.asc")
    with pytest.raises(FogmonError, match=r"cycle time of gnss_imu \(20 ms\) says 50 Hz but the time stamps say "
                                          r"99\.907"):
        open_replay_source(path, SourceOptions(dbc=DBC_20MS, can_rate="AngularRateZ"))
    with pytest.raises(FogmonError, match=r"sample_rate_hz says 50 Hz .* force_rate"):
        open_replay_source(path, SourceOptions(dbc=DBC, can_rate="AngularRateZ", sample_rate_hz=50.0))
    forced = open_replay_source(path, SourceOptions(dbc=DBC_20MS, can_rate="AngularRateZ", force_rate=True))
    assert forced.sample_rate_hz == 50.0 and forced.n_samples == 800


def test_bursty_can_log_with_a_gap_reads_and_counts_the_gap():
    path = os.path.join(CAN_DIR, "canmod_imu_bursty_35s.mf4")
    src = open_replay_source(path, SourceOptions(dbc=DBC, can_rate="AngularRateZ"))
    blocks = list(src.blocks())
    gaps = [e for b in blocks for e in b.events if e.kind == "gap"]
    assert src.counters["seq_gaps"] == 1 and 40 <= src.counters["samples_missing"] <= 50
    assert "port reopened" not in gaps[0].message and "time gap in" in gaps[0].message
    assert path in gaps[0].message
    assert src.sample_rate_hz == pytest.approx(98.45, abs=0.05)


def test_can_message_absent_from_the_log_names_the_file_and_the_ids():
    path = os.path.join(CAN_DIR, "canmod_imu_8s.log")
    with pytest.raises(FogmonError, match=r"canmod_imu_8s\.log: 0 frame\(s\) of DBC message Foo .* ids: 0x1 \(8\)"):
        open_replay_source(path, SourceOptions(dbc=os.path.join(CAN_DIR, "cantools_timing.dbc"), can_rate="Foo",
                                               can_message="Foo", can_rate_unit="deg/s"))


def test_mdf4_channel_matches_asammdf_and_the_list_points_to_info():
    import asammdf
    path = pub("mdf", "canmod_imu_decoded_8s.mf4")
    with pytest.raises(FogmonError, match=r"165 channels, listed by: fogmon info .*canmod_imu_decoded_8s\.mf4") as e:
        open_replay_source(path)
    assert "more" not in str(e.value)
    rec = read_recording(path, SourceOptions(channel="AngularRateZ"))
    with asammdf.MDF(path) as mdf:
        sig = mdf.get("AngularRateZ")
    np.testing.assert_allclose(rec.rate_dph, np.asarray(sig.samples, float) * 3600.0, rtol=1e-12)
    assert rec.sample_rate_hz == pytest.approx(99.907, abs=0.001)
    same_adev(rec)
    entries = file_info(path)
    assert {e.name for e in entries} >= set(mdf_names(path))
    assert {e.unit for e in entries if e.name == "AngularRateZ"} == {"deg/s"}


def mdf_names(path: str) -> list[str]:
    import asammdf
    with asammdf.MDF(path) as mdf:
        return [n for n in mdf.channels_db if n not in ("t", "time")]


def test_las_clock_and_date_time_curves_are_time():
    path = pub("las", "time_hhmmss_date.las")
    rec = read_recording(path, SourceOptions(channel="ARC_GR_UNC_RT", rate_unit="deg/s"))
    np.testing.assert_array_equal(rec.t_s, [0.0, 1.0])
    np.testing.assert_array_equal(rec.rate_dph, [126.56 * 3600.0] * 2)
    e = {x.name: x for x in file_info(path)}
    assert e["TIME"].rate_hz == 1.0 and e["TIME"].unit == "HHMMSS"


def test_info_of_every_public_file_exits_0_and_lists_every_part(capsys):
    from fogmon.cli import main
    for path, opts in [(pub("ulog", "sample_bench_8s.ulg"), []), (pub("ros1", "husky_imu_30hz_40s.bag"), []),
                       (pub("ros2", "talker"), []), (os.path.join(CAN_DIR, "canmod_imu_8s.trc"), ["--dbc", DBC]),
                       (pub("las", "etim_seconds.las"), [])]:
        assert main(["info", path, *opts]) == 0
        out = capsys.readouterr().out.splitlines()
        assert out[0].split() == ["name", "type", "count", "rate_hz", "span_s", "unit"] and len(out) >= 2
    assert main(["info", pub("nope.ulg")]) == 2
    assert "no such file" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["replay", "explain", "sim", "convert", "batch", "thermal", "inorbit", "updown",
                                     "info"])
def test_every_command_reading_recordings_has_the_reader_options(command):
    import importlib

    from fogmon.cli import _Parser, flag_table
    p = _Parser(prog=f"fogmon {command}")
    importlib.import_module(f"fogmon.cli.{command}").add_arguments(p)
    flags = set(flag_table(p).values())
    assert {"--topic", "--channel", "--time-channel", "--rate-unit", "--dbc", "--can-rate", "--axis",
            "--resample-hz", "--force-rate", "--rate-hz"} <= flags


def test_implausible_numbers_are_errors_not_allocations(tmp_path):
    csv = tmp_path / "far.csv"
    csv.write_text("time_s,rate_dph\n" + "".join(f"{k / 100},1\n" for k in range(99)) + "1e7,1\n")
    with pytest.raises(FogmonError, match="corrupt time stamp or sample rate"):
        open_replay_source(str(csv))
    fast = tmp_path / "fast.csv"
    fast.write_text("# sample_rate_hz: 1e12\ntime_s,rate_dph\n0,1\n0.01,1\n")
    with pytest.raises(FogmonError, match="sample_rate_hz must be > 0 and <= 1e"):
        open_replay_source(str(fast))
    wrong = tmp_path / "wrong.csv"
    wrong.write_text("# sample_rate_hz: 100\ntime_s,rate_dph\n" + "".join(f"{k / 50},1\n" for k in range(50)))
    with pytest.raises(FogmonError, match="says 100 Hz but column time_s steps by 0.02 s"):
        open_replay_source(str(wrong))
    assert open_replay_source(str(wrong), SourceOptions(force_rate=True)).n_samples == 99
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert math.isclose(read_recording(str(wrong), SourceOptions(force_rate=True)).sample_rate_hz, 100.0)


def test_mdf4_channel_beyond_its_record_is_one_line_not_a_crash(tmp_path):
    """A corrupt channel byte offset (found by validation/fuzz_readers.py) made asammdf's C
    extension read out of bounds: the process died. The layout is checked first."""
    import struct

    import asammdf
    src = pub("mdf", "canmod_imu_decoded_8s.mf4")
    with asammdf.MDF(src) as mdf:
        ch = mdf.groups[8].channels[0]
        where = ch.address + 24 + 8 * ch.links_nr + 4       # cn_byte_offset: after header, links, 4 bytes
    with open(src, "rb") as fh:
        data = bytearray(fh.read())
    data[where:where + 4] = struct.pack("<I", 1 << 20)
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(data))
    for read in (lambda: file_info(str(bad)),
                 lambda: open_replay_source(str(bad), SourceOptions(channel="AngularRateZ"))):
        with pytest.raises(FogmonError, match=r"bad\.mf4: not a readable MDF file \(corrupt: channel 'time' of data "
                                              r"group 8 ends at byte 1048584 of a 23-byte record\)"):
            read()


def test_mf4_can_log_with_a_corrupt_record_is_one_line_not_a_crash(tmp_path):
    """asammdf decodes an MF4 CAN log while opening it (python-can's reader): a corrupt
    channel killed the process there (fuzz_readers.py); the layout is checked first."""
    import struct

    import asammdf
    src = os.path.join(CAN_DIR, "canmod_imu_8s.mf4")
    with asammdf.MDF(src, process_bus_logging=False) as mdf:   # type: ignore[call-arg]
        ch = mdf.groups[0].channels[0]
        where = ch.address + 24 + 8 * ch.links_nr + 4
    with open(src, "rb") as fh:
        data = bytearray(fh.read())
    data[where:where + 4] = struct.pack("<I", 1 << 20)
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(data))
    with pytest.raises(FogmonError, match=r"bad\.mf4: not a readable MDF file \(corrupt: channel .* of data group 0"):
        open_replay_source(str(bad), SourceOptions(dbc=os.path.join(CAN_DIR, "canmod-gps.dbc"),
                                                   can_rate="AngularRateZ"))


def test_mdf4_record_larger_than_its_data_is_one_line_not_a_long_allocation(tmp_path):
    """A flipped bit in a channel group's record size made asammdf allocate GBs and sit
    for minutes (fuzz_readers.py): a record larger than the group's data is refused."""
    import struct

    import asammdf
    src = pub("mdf", "canmod_imu_decoded_8s.mf4")
    with asammdf.MDF(src) as mdf:
        cg = mdf.groups[2].channel_group
        where = cg.address + 24 + 8 * cg.links_nr + 24      # cg_data_bytes: after record id, cycles, flags
    with open(src, "rb") as fh:
        data = bytearray(fh.read())
    assert struct.unpack("<I", data[where:where + 4]) == (22,)
    data[where:where + 4] = struct.pack("<I", 1 << 30)
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(data))
    with pytest.raises(FogmonError, match=r"bad\.mf4: not a readable MDF file \(corrupt: data group 2 has "
                                          r"1073741824-byte records but its data blocks hold 176 bytes\)"):
        file_info(str(bad))
