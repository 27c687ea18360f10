"""Several axes at the live sources and the archive: a fake three-axis KVH DSP-1760 on a
pty (all gyros and accelerometers, per-axis status bits, corruption, garbage and dropped
frames) decoded to exactly the values sent per axis; the archive's replay log holds them
(rows where every axis is valid, the rest counted) and its raw capture decodes to the
same blocks; ``--axis`` one axis as before; generic lines with one rate column per axis;
CAN with the axes' signals in two messages of a DBC on a python-can virtual bus."""
import json
import os
import threading
import time
import uuid

import can
import numpy as np
import pytest
import serial
from helpers.doubles import args_for
from helpers.fake_device import MAX_RATE_DPH, open_pty, write_all

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.formats.capture import read_sidecar
from fogmon.sinks.archive import Archive
from fogmon.sinks.base import Summary
from fogmon.sources.codecs.can import CanDecoder
from fogmon.sources.codecs.kvh import G0_MPS2, KvhCodec, encode_frame
from fogmon.sources.codecs.lines import LinesCodec
from fogmon.sources.codecs.protocols import make_codec
from fogmon.sources.devices.can_bus import CanSource
from fogmon.sources.devices.serial_port import SerialSource
from fogmon.sources.files.capture import open_raw_capture
from fogmon.sources.open import open_live_source, open_replay_source

FS = 200.0
N = 300
#: frame k -> what goes wrong with it
FAULTS = {5: "corrupt", 6: "drop", 7: "drop", 40: "garbage", 90: "corrupt", 130: "drop", 200: "garbage"}
#: frame k -> status byte (bits 0-2 gyro x/y/z valid, 4-6 accel x/y/z valid; 0x77 = all)
STATUS = {20: 0x76, 21: 0x75, 22: 0x73, 50: 0x70, 60: 0x07}


def sent(k: int) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Gyro x/y/z (deg/s, rate mode) and accel x/y/z (g) of frame k: distinct per axis
    and exact in float32."""
    return (float(k), -0.5 * k, 1000.0 + k), (0.25 * (k % 8), -0.125 * (k % 4), 1.0 + 0.5 * (k % 2))


def kvh_stream() -> tuple[bytes, list[int]]:
    """Frames 0..N-1 with FAULTS and STATUS applied, and the k of the frames that arrive intact."""
    out, intact = [], []
    for k in range(N):
        gyro, accel = sent(k)
        f = encode_frame("a", k % 128, gyro, accel, status=STATUS.get(k, 0x77), temp_c=20 + k % 5)
        kind = FAULTS.get(k)
        if kind == "drop":
            continue
        if kind == "corrupt":
            f = f[:10] + bytes([f[10] ^ 0x5A]) + f[11:]
        else:
            intact.append(k)
        if kind == "garbage":
            out.append(bytes((k * 37 + i) % 200 + 1 for i in range(13)))   # never 0xFE
        out.append(f)
    return b"".join(out), intact


def expected(intact: list[int]):
    """What a three-axis decoder must give on the grid 0..N-1: rate (deg/h), valid per axis, accel (g)."""
    rate = np.full((N, 3), np.nan)
    valid = np.zeros((N, 3), bool)
    accel = np.full((N, 3), np.nan)
    for k in intact:
        gyro, acc = sent(k)
        st = STATUS.get(k, 0x77)
        for j in range(3):
            valid[k, j] = bool(st >> j & 1)
            rate[k, j] = 3600.0 * gyro[j] if valid[k, j] else np.nan
            accel[k, j] = acc[j] if st >> (j + 4) & 1 else np.nan
    return rate, valid, accel


def three_axis_codec(**kw) -> KvhCodec:
    return KvhCodec("a", "rate", "deg", sample_rate_hz=FS, max_rate_dph=MAX_RATE_DPH, **kw)


def test_codec_decodes_every_gyro_and_accelerometer_and_one_axis_as_before():
    data, intact = kvh_stream()
    c = three_axis_codec()
    f = c.feed(data)
    assert f.axes == ("x", "y", "z") and c.axes == ("x", "y", "z")
    assert c.aux_names == ("accel_x_g", "accel_y_g", "accel_z_g", "temp_c")
    rate, valid, accel = expected(intact)
    sent_dph = 3600.0 * np.array([sent(k)[0] for k in intact])     # frames keep what was sent, valid or not
    np.testing.assert_array_equal(f.rate_dph, sent_dph)
    np.testing.assert_array_equal(f.valid, valid[intact])
    for j, a in enumerate("xyz"):
        np.testing.assert_array_equal(f.aux[f"accel_{a}_g"], accel[intact, j])
    assert c.options()["axis"] == "x,y,z" and c.options()["kvh_accel"] == "g"
    # --axis z: the one-axis stream of earlier versions (no accelerometers, same options)
    z = three_axis_codec(axis="z")
    fz = z.feed(data)
    assert fz.axes == () and fz.rate_dph.shape == (len(intact),) and list(fz.aux) == ["temp_c"]
    np.testing.assert_array_equal(fz.rate_dph, sent_dph[:, 2])
    np.testing.assert_array_equal(fz.valid, valid[intact, 2])
    assert z.options() == {"protocol": "kvh-a", "kvh_rot": "rate", "kvh_units": "deg", "axis": "z",
                           "sample_rate_hz": FS, "max_rate_dph": MAX_RATE_DPH}
    assert c.counters.pop("implausible_accel_g") == 0 and z.counters == c.counters
    # --axis y,x: those gyros in that order, with their accelerometers
    yx = three_axis_codec(axis="y,x").feed(data)
    assert yx.axes == ("y", "x") and set(yx.aux) == {"accel_y_g", "accel_x_g", "temp_c"}
    np.testing.assert_array_equal(yx.rate_dph, sent_dph[:, [1, 0]])


def test_accelerometer_units_and_bad_options():
    gyro, accel_g = (0.0, 0.0, 0.0), (0.5, -1.0, 2.0)
    dv_mps = tuple(a * G0_MPS2 / FS for a in accel_g)          # velocity increment per sample, m/s
    f = KvhCodec("b", sample_rate_hz=FS, accel="dv-m").feed(encode_frame("b", 0, gyro, dv_mps))
    np.testing.assert_allclose([f.aux[f"accel_{a}_g"][0] for a in "xyz"], accel_g, rtol=1e-6)
    dv_fps = tuple(a * G0_MPS2 / 0.3048 / FS for a in accel_g)
    f = KvhCodec("c", sample_rate_hz=FS, accel="dv-ft").feed(encode_frame("c", 0, gyro, dv_fps))
    np.testing.assert_allclose([f.aux[f"accel_{a}_g"][0] for a in "xyz"], accel_g, rtol=1e-6)
    # a CRC-valid garbage float (or NaN) in an accelerometer field flagged valid: NaN, counted
    c = KvhCodec("a")
    f = c.feed(encode_frame("a", 0, gyro, (1e30, np.nan, -49.0))
               + encode_frame("a", 1, gyro, (1e30, 0, 0), status=0x07))          # accelerometers flagged invalid
    np.testing.assert_array_equal([f.aux[f"accel_{a}_g"][0] for a in "xyz"], [np.nan, np.nan, -49.0])
    assert np.isnan([f.aux[f"accel_{a}_g"][1] for a in "xyz"]).all() and c.counters["implausible_accel_g"] == 2
    c = KvhCodec("a", accel="none")
    assert c.aux_names == ("temp_c",) and c.axes == ("x", "y", "z") and c.options()["kvh_accel"] == "none"
    for kw, msg in [({"axis": "q"}, "^axis must be x, y, z"), ({"axis": "x,x"}, "^axis x,x: an axis is named twice$"),
                    ({"accel": "mps"}, "^kvh_accel must be one of")]:
        with pytest.raises(FogmonError, match=msg):
            KvhCodec("a", **kw)


def read_archive_csv(path: str) -> tuple[list[str], np.ndarray]:
    with open(path, encoding="utf-8") as fh:
        rows = [ln.strip() for ln in fh if not ln.startswith("#")]
    return rows[0].split(","), np.array([[float(x) for x in r.split(",")] for r in rows[1:]])


def concat(blocks: list[Block]) -> Block:
    return Block.concat([b for b in blocks if len(b)])


def assert_same_samples(a: Block, b: Block) -> None:
    assert a.axes == b.axes and set(a.aux) == set(b.aux)
    np.testing.assert_array_equal(a.t_s, b.t_s)
    np.testing.assert_array_equal(a.rate_dph, b.rate_dph)
    np.testing.assert_array_equal(a.valid, b.valid)
    for k in a.aux:
        np.testing.assert_array_equal(a.aux[k], b.aux[k])


def test_fake_three_axis_kvh_on_a_pty_archive_and_replay(tmp_path):
    data, intact = kvh_stream()
    master, slave, path = open_pty()
    src = SerialSource(path, 921600, three_axis_codec())
    assert src.axes == ("x", "y", "z")
    archive = Archive(str(tmp_path / "arch"), src, background_flush=False)

    def device():
        while src._thread is None:          # the reader runs once the port is open and flushed
            time.sleep(0.005)
        write_all(master, data, timeout_s=30)

    th = threading.Thread(target=device)
    th.start()
    blocks = []
    try:
        for b in src.blocks():
            blocks.append(b)
            archive.block(b)
            if sum(len(x) for x in blocks) >= N:
                break
    finally:
        src.close()
        th.join()
        os.close(master)
        os.close(slave)
    summary = Summary(src.name, FS, 1.0, 1.0)
    archive.finish(summary)
    live = concat(blocks)
    rate, valid, accel = expected(intact)
    assert live.axes == ("x", "y", "z") and len(live) == N
    np.testing.assert_array_equal(live.t_s, np.arange(N) / FS)
    np.testing.assert_array_equal(live.rate_dph, rate)            # exactly the values sent, per axis
    np.testing.assert_array_equal(live.valid, valid)              # invalid where lost or flagged
    for j, a in enumerate("xyz"):
        np.testing.assert_array_equal(live.aux[f"accel_{a}_g"], accel[:, j])
    c = src.counters
    lost = N - len(intact)
    assert c["samples_missing"] == lost == 5 and c["seq_gaps"] == 3 and c["crc_errors"] == 2
    assert c["invalid_samples"] == 4                                # frames 20, 21, 22, 50
    assert (c["invalid_samples_x"], c["invalid_samples_y"], c["invalid_samples_z"]) == (2, 2, 2)

    # the replay log: a row where every axis is valid and every accelerometer gave a value
    header, rows = read_archive_csv(archive.replay_log_path)
    assert header == ["time_s", "rate_x_dph", "rate_y_dph", "rate_z_dph", "accel_x_g", "accel_y_g", "accel_z_g",
                      "temp_c"]
    full = valid.all(axis=1) & np.isfinite(accel).all(axis=1)
    np.testing.assert_allclose(rows[:, 0] * FS, np.flatnonzero(full), atol=1e-6)
    np.testing.assert_array_equal(rows[:, 1:4], rate[full])
    np.testing.assert_array_equal(rows[:, 4:7], accel[full])
    partial = int((valid.any(axis=1) & ~valid.all(axis=1)).sum())
    assert archive.counters["partial_samples_dropped"] == partial == 3        # 20, 21, 22
    assert archive.counters["rows_without_aux"] == 1                         # 60: accelerometers invalid
    assert archive.counters["rows_written"] == len(rows)
    assert f"{partial} with only some axes valid left out of the replay log" in summary.outputs[0]

    # the raw capture decodes to the same blocks (sidecar: every axis)
    side = read_sidecar(archive.capture_path)
    assert side["axis"] == "x,y,z" and side["kvh_accel"] == "g"
    assert_same_samples(concat(list(open_raw_capture(archive.capture_path).blocks())), live)
    # ... and with --axis z to the one-axis stream
    one = concat(list(open_raw_capture(archive.capture_path, {"axis": "z"}).blocks()))
    assert one.axes == () and list(one.aux) == ["temp_c"]
    np.testing.assert_array_equal(one.rate_dph, live.rate_dph[:, 2])
    np.testing.assert_array_equal(one.valid, live.valid[:, 2])


def test_sidecar_of_earlier_versions_decodes_one_axis_and_new_values_are_checked(tmp_path):
    data, intact = kvh_stream()
    cap = tmp_path / "raw-0001.bin"
    cap.write_bytes(data)
    old = {"format": "fogmon capture v1", "kind": "serial", "protocol": "kvh-a", "kvh_rot": "rate",
           "kvh_units": "deg", "axis": "y", "sample_rate_hz": FS, "max_rate_dph": MAX_RATE_DPH, "breaks": []}
    (tmp_path / "raw-0001.bin.json").write_text(json.dumps(old))
    b = concat(list(open_raw_capture(str(cap)).blocks()))
    rate, valid, _ = expected(intact)
    assert b.axes == () and list(b.aux) == ["temp_c"]
    np.testing.assert_array_equal(b.rate_dph, rate[:, 1])
    np.testing.assert_array_equal(b.valid, valid[:, 1])
    for field, value in [("axis", "x,x"), ("axis", "x y"), ("axis", 3), ("kvh_accel", "mps2")]:
        (tmp_path / "raw-0001.bin.json").write_text(json.dumps({**old, field: value}))
        with pytest.raises(FogmonError, match=f"raw-0001.bin.json: field {field}: "):
            open_raw_capture(str(cap))


def test_lines_with_one_rate_column_per_axis():
    c = LinesCodec("seq:16,rate_x_dph,rate_y_dps,delta_z_rad,valid_y,temp_c", sample_rate_hz=100)
    f = c.feed(b"0,1.5,2,0.001,1,25\n1,-1.5,-2,-0.001,0,25.5\n2,x\n3,7,0.5,0,1,26\n")
    assert f.axes == c.axes == ("x", "y", "z") and c.aux_names == ("temp_c",)
    np.testing.assert_allclose(f.rate_dph, [[1.5, 7200, 0.001 * 180 / np.pi * 3600 * 100],
                                            [-1.5, -7200, -0.001 * 180 / np.pi * 3600 * 100],
                                            [7, 1800, 0]])
    np.testing.assert_array_equal(f.valid, [[True, True, True], [True, False, True], [True, True, True]])
    assert c.counters["bad_lines"] == 1 and list(f.seq) == [0, 1, 3]
    assert "axis" not in c.options()
    # --axis picks some: one is a one-axis stream, recorded in the options (capture sidecar)
    z = make_codec("lines", 100, columns="rate_x_dph,rate_z_dph", axis="z")
    fz = z.feed(b"1,2\n3,4\n")
    assert z.axes == () and list(fz.rate_dph) == [2, 4] and z.options()["axis"] == "z"
    assert make_codec("lines", 100, columns="rate_dph", axis="z").options() == LinesCodec().options() | {
        "sample_rate_hz": 100.0}                                     # one rate column: --axis changes nothing
    with pytest.raises(FogmonError, match="no rate column of axis q"):
        make_codec("lines", columns="rate_x_dph,rate_y_dph", axis="q")
    for bad in ("rate_dph,rate_x_dph", "rate_x_dph,rate_x_dps", "temp_c"):
        with pytest.raises(FogmonError, match="exactly one rate column"):
            LinesCodec(bad)


DBC_TWO_MESSAGES = """VERSION ""

NS_ :

BS_:

BU_: IMU MONITOR

BO_ 288 GYRO_XY: 8 IMU
 SG_ GyroX : 0|24@1- (0.001,0) [-8388.608|8388.607] "deg/s" MONITOR
 SG_ GyroY : 24|24@1- (0.001,0) [-8388.608|8388.607] "deg/h" MONITOR
 SG_ counter : 48|4@1+ (1,0) [0|15] "" MONITOR
 SG_ valid : 52|1@1+ (1,0) [0|1] "" MONITOR

BO_ 289 GYRO_Z: 4 IMU
 SG_ GyroZ : 0|32@1- (1E-006,0) [-2147.483648|2147.483647] "rad/s" MONITOR

BA_DEF_ BO_  "GenMsgCycleTime" INT 0 65535;
BA_DEF_DEF_  "GenMsgCycleTime" 0;
BA_ "GenMsgCycleTime" BO_ 288 10;
BA_ "GenMsgCycleTime" BO_ 289 10;
"""


def imu_msgs(ks, lost_z=(), extra_z=(), t0=1_000_000.0):
    """Sample k: GyroZ frame (sent first in its period, unless lost; twice for extra_z), then
    GyroX = k/1000 deg/s, GyroY = -k/1000 deg/h with counter k % 16."""
    db = load_dbc_text(DBC_TWO_MESSAGES)
    xy, z = db.get_message_by_name("GYRO_XY"), db.get_message_by_name("GYRO_Z")
    out = []
    for k in ks:
        t = t0 + k / 100.0
        for _ in range(2 if k in extra_z else 0 if k in lost_z else 1):
            out.append(can.Message(timestamp=t, arbitration_id=289, is_extended_id=False,
                                   data=z.encode({"GyroZ": 1e-3 * k})))
        out.append(can.Message(timestamp=t + 1e-3, arbitration_id=288, is_extended_id=False,
                               data=xy.encode({"GyroX": 1e-3 * k, "GyroY": -1e-3 * k, "counter": k % 16,
                                               "valid": 1})))
    return out


def load_dbc_text(text: str):
    import cantools
    return cantools.database.load_string(text, database_format="dbc")


def test_can_decoder_joins_axes_of_two_messages_on_the_clock_message():
    d = CanDecoder(load_dbc_text(DBC_TWO_MESSAGES), rate_signal="x=GyroX,y=GyroY,z=GyroZ")
    assert d.axes == ("x", "y", "z") and d.message.name == "GYRO_XY" and d.sample_rate_hz == 100.0
    (brk, f), = d.feed(imu_msgs(range(20), lost_z=(5, 6), extra_z=(12,)))
    assert brk is None and f.axes == ("x", "y", "z")
    k = np.arange(20)
    np.testing.assert_allclose(f.rate_dph[:, 0], 3.6 * k, rtol=1e-9)
    np.testing.assert_allclose(f.rate_dph[:, 1], -1e-3 * k, rtol=1e-9)
    z_ok = ~np.isin(k, (5, 6))
    np.testing.assert_allclose(f.rate_dph[z_ok, 2], 1e-3 * k[z_ok] * 180 / np.pi * 3600, rtol=1e-9)
    assert np.isnan(f.rate_dph[~z_ok, 2]).all()
    np.testing.assert_array_equal(f.valid, np.column_stack([np.ones(20, bool), np.ones(20, bool), z_ok]))
    assert d.counters["axis_frames_missing_z"] == 2 and d.counters["axis_frames_superseded"] == 1
    assert d.options()["rate_signal"] == "x=GyroX,y=GyroY,z=GyroZ" and d.options()["rate_unit"] is None
    for spec, msg in [("x=GyroX,x=GyroY", "distinct axis"), ("x=GyroX,y=Nope", "Nope")]:
        with pytest.raises(FogmonError, match=msg):
            CanDecoder(load_dbc_text(DBC_TWO_MESSAGES), rate_signal=spec)


def test_can_source_on_a_virtual_bus_with_axes_in_two_messages_archive_and_replay(tmp_path):
    dbc = tmp_path / "imu.dbc"
    dbc.write_text(DBC_TWO_MESSAGES)
    ch = f"fogmon-{uuid.uuid4().hex}"
    src = open_live_source(args_for("--can", ch, "--interface", "virtual", "--dbc", str(dbc),
                                    "--can-rate", "x=GyroX,y=GyroY,z=GyroZ"))
    assert isinstance(src, CanSource) and src.axes == ("x", "y", "z")
    assert src.name.startswith("CAN axes x=GYRO_XY.GyroX, y=GYRO_XY.GyroY, z=GYRO_Z.GyroZ (clock GYRO_XY), 100 Hz")
    archive = Archive(str(tmp_path / "arch"), src, background_flush=False)
    ks = [k for k in range(120) if k not in (30, 31)]        # two clock frames lost: a gap on every axis
    msgs = imu_msgs(ks, lost_z=(50,), t0=time.time())

    def device():
        while src._thread is None:
            time.sleep(0.005)
        with can.Bus(interface="virtual", channel=ch, preserve_timestamps=True) as tx:
            for m in msgs:
                tx.send(m)

    th = threading.Thread(target=device)
    th.start()
    blocks = []
    try:
        for b in src.blocks():
            blocks.append(b)
            archive.block(b)
            if src.counters["frames_ok"] >= len(ks):
                break
    finally:
        src.close()
        th.join()
    archive.close()
    live = concat(blocks)
    assert live.axes == ("x", "y", "z") and len(live) == 120
    v = live.valid
    assert not v[[30, 31]].any() and list(v[50]) == [True, True, False]
    assert v.sum() == 3 * 118 - 1 and src.counters["axis_frames_missing_z"] == 1
    np.testing.assert_allclose(live.rate_dph[v[:, 0], 0], 3.6 * np.array(ks), rtol=1e-9)
    header, rows = read_archive_csv(archive.replay_log_path)
    assert header == ["time_s", "rate_x_dph", "rate_y_dph", "rate_z_dph"] and len(rows) == 117
    assert archive.counters["partial_samples_dropped"] == 1
    # the ASC capture with its sidecar (the DBC copy beside it) decodes to the same blocks
    assert_same_samples(concat(list(open_replay_source(archive.capture_path, args_for()).blocks())), live)


def test_lines_with_three_rate_columns_on_a_serial_port():
    port = serial.serial_for_url("loop://", timeout=0.05)
    lines = [f"{k % 16},{k},{-k},{2 * k},{int(k != 20)}\n".encode() for k in range(40) if k not in (10, 11)]
    port.write(b"".join(lines[:15]) + b"BOOT\n" + b"".join(lines[15:]))
    src = SerialSource("loop://", 115200, LinesCodec("seq:16,rate_x_dph,rate_y_dph,rate_z_dph,valid_z", 100.0),
                       opener=lambda: port)
    assert src.axes == ("x", "y", "z")
    blocks = []
    for b in src.blocks():
        blocks.append(b)
        if sum(len(x) for x in blocks) >= 40:
            break
    src.close()
    b = concat(blocks)
    k = np.arange(40)
    lost = np.isin(k, (10, 11))
    np.testing.assert_array_equal(b.valid, np.column_stack([~lost, ~lost, ~lost & (k != 20)]))
    want = np.column_stack([k, -k, 2 * k]).astype(float)
    want[~b.valid] = np.nan                                           # lost samples and z at k = 20
    np.testing.assert_array_equal(b.rate_dph, want)
    assert src.counters["samples_missing"] == 2 and src.counters["bad_lines"] == 1
    assert src.counters["invalid_samples_z"] == 1 and src.counters["invalid_samples_x"] == 0


def test_convert_writes_a_multi_axis_replay_log_by_the_archive_rule(tmp_path, capsys):
    from fogmon.cli import main
    data, intact = kvh_stream()
    raw = tmp_path / "raw.bin"
    raw.write_bytes(data)
    opts = ["--protocol", "kvh-a", "--kvh-rot", "rate", "--kvh-units", "deg", "--rate-hz", str(FS),
            "--max-rate-dph", str(MAX_RATE_DPH)]
    assert main(["convert", str(raw), str(tmp_path / "out.csv"), *opts]) == 0
    assert "3 samples with only some axes valid left out" in capsys.readouterr().out
    header, rows = read_archive_csv(str(tmp_path / "out.csv"))
    rate, valid, accel = expected(intact)
    full = valid.all(axis=1) & np.isfinite(accel).all(axis=1)
    assert header[:4] == ["time_s", "rate_x_dph", "rate_y_dph", "rate_z_dph"]
    np.testing.assert_array_equal(rows[:, 1:4], rate[full])
    assert main(["convert", str(raw), str(tmp_path / "out.parquet"), *opts]) == 0
    from fogmon.formats.parquet_log import read_parquet_log
    back = read_parquet_log(tmp_path / "out.parquet")
    assert back.axes == ("x", "y", "z")
    np.testing.assert_array_equal(back.rate_dph, rate[full])


def test_duration_limit_cuts_a_three_axis_stream_at_its_last_sample_and_the_capture_with_it(tmp_path):
    data, intact = kvh_stream()
    port = serial.serial_for_url("loop://", timeout=0.05)
    src = SerialSource("loop://", 921600, three_axis_codec(), opener=lambda: port)
    src.limit(100)
    archive = Archive(str(tmp_path / "arch"), src, background_flush=False)
    port.write(data[:4000])                     # loop:// holds 4096 bytes: frames 0..110, faults included
    blocks = []
    for b in src.blocks():
        blocks.append(b)
        archive.block(b)
    archive.close()
    live = concat(blocks)
    rate, valid, _ = expected(intact)
    assert len(live) == 100
    np.testing.assert_array_equal(live.rate_dph, rate[:100])
    np.testing.assert_array_equal(live.valid, valid[:100])
    assert src.counters["frames_ok"] == sum(k < 100 for k in intact)
    assert_same_samples(concat(list(open_raw_capture(archive.capture_path).blocks())), live)
