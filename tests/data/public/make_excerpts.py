"""Rebuild the public test files of this folder from repository snapshots (PROVENANCE.md).

Usage:
    python tests/data/public/make_excerpts.py [MIRROR] [--out DIR] [--check]

MIRROR: a folder holding repository snapshots as ``owner+name/repo`` bare git
directories (default /work/.mirror). Every original is read with ``git show
COMMIT:PATH`` at the commit PROVENANCE.md names and its sha256 checked; each file here
is either that original or an excerpt cut by the format's own library (pyulog, rosbags,
asammdf, python-can). ``--check`` compares what it builds with the files already here,
without writing: byte for byte, except the CAN logs and MDF4 files, whose writers stamp
the time of writing (and the ASC/TRC writers a path) into their headers: those are
compared frame by frame (python-can) or channel by channel (asammdf). Needs
``fogmon[formats]`` plus python-can's MF4 support (asammdf), all in fogmon's test extras.
"""
from __future__ import annotations

import argparse
import hashlib
import io
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent

PYULOG = ("PX4/pyulog", "3cf17793f14709713ab297d3743314c658874068")
ROBOT_LOC = ("cra-ros-pkg/robot_localization", "1cb953379378d13b3e0935ed73d0c7407bd80543")
ROSBAG2 = ("ros2/rosbag2", "25304dd36e51cc0fbccf148fded2dd4ba5ccba35")
CSS = ("CSS-Electronics/api-examples", "f7932bacb2969dec591508d15f89e8a898ca99c6")
CANTOOLS = ("cantools/cantools", "c1dcd3968abc66aae9558605711a6bb7c718a6b7")
LASIO = ("kinverarity1/lasio", "9e32ea67f8589955e62d979251c514d290e00b9c")
IMU_UTILS = ("gaowenliang/imu_utils", "2cdda91d5b7206517abb080e585c4f2793e523f1")

# sha256 of every original read (a changed snapshot is an error, not a new excerpt)
ORIGINAL_SHA256 = {
    "test/sample.ulg": "81952e6059bc095717e7911c010e07f85749d6b04d332a5ffc51575a3fd0a558",
}


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


class Mirror:
    def __init__(self, root: Path) -> None:
        self.root = root

    def read(self, src: tuple[str, str], path: str) -> bytes:
        repo, commit = src
        git = self.root / repo.replace("/", "+") / "repo"
        if not (git / "objects").is_dir():
            raise SystemExit(f"no snapshot of {repo} under {self.root} (fetch github:{repo})")
        data = subprocess.run(["git", f"--git-dir={git}", "show", f"{commit}:{path}"],
                              check=True, capture_output=True).stdout
        want = ORIGINAL_SHA256.get(path)
        if want and sha256(data) != want:
            raise SystemExit(f"{repo}@{commit}:{path} has sha256 {sha256(data)}, expected {want}")
        return data


# --------------------------------------------------------------------------- ULog
def ulog_excerpt(data: bytes, topics: list[str], t0_s: float, t1_s: float) -> bytes:
    """The ULog ``data`` with only ``topics``, every message of them with a timestamp in
    [t0_s, t1_s) s after the first logged sample of those topics, logged text messages,
    dropouts and parameter changes in that window too; the header, formats, info and
    initial parameters unchanged. Written by pyulog's own writer."""
    import numpy as np
    import pyulog

    log = pyulog.ULog(io.BytesIO(data), topics)
    first = min(int(d.data["timestamp"][0]) for d in log.data_list)
    lo, hi = first + round(t0_s * 1e6), first + round(t1_s * 1e6)
    for d in log.data_list:
        ts = d.data["timestamp"].astype(np.int64)
        keep = (ts >= lo) & (ts < hi)
        d.data = {k: v[keep] for k, v in d.data.items()}
    log._data_list = [d for d in log.data_list if len(d.data["timestamp"])]
    log._logged_messages = [m for m in log.logged_messages if lo <= m.timestamp < hi]
    for tag in list(log._logged_messages_tagged):
        log._logged_messages_tagged[tag] = [m for m in log._logged_messages_tagged[tag]
                                            if lo <= m.timestamp < hi]
    log._dropouts = [d for d in log.dropouts if lo <= d.timestamp < hi]
    log._changed_parameters = [p for p in log.changed_parameters if lo <= p[0] < hi]
    out = io.BytesIO()
    log.write_ulog(out)
    return out.getvalue()


# --------------------------------------------------------------------------- ROS 1
def rosbag1_excerpt(data: bytes, t0_s: float, t1_s: float) -> bytes:
    """The ROS 1 bag ``data`` with every message whose record time lies in [t0_s, t1_s)
    s after the bag's start, raw bytes and connection definitions unchanged, chunks
    bz2-compressed as in the originals (rosbags)."""
    from rosbags.interfaces import ConnectionExtRosbag1
    from rosbags.rosbag1 import Reader, Writer

    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.bag", Path(tmp) / "out.bag"
        src.write_bytes(data)
        writer = Writer(dst)
        writer.set_compression(Writer.CompressionFormat.BZ2)
        with Reader(src) as reader, writer:
            lo = reader.start_time + round(t0_s * 1e9)
            hi = reader.start_time + round(t1_s * 1e9)
            conns = {}
            for c in reader.connections:
                ext = c.ext
                assert isinstance(ext, ConnectionExtRosbag1)
                conns[c.id] = writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data,
                                                    md5sum=c.digest, callerid=ext.callerid,
                                                    latching=ext.latching)
            for c, t, raw in reader.messages():
                if lo <= t < hi:
                    writer.write(conns[c.id], t, raw)
        return dst.read_bytes()


# --------------------------------------------------------------------------- CAN / MDF4
def mf4_excerpt(data: bytes, t0_s: float, t1_s: float) -> bytes:
    """The MDF4 bus log ``data`` cut to [t0_s, t1_s] s after its start (asammdf's cut)."""
    from asammdf import MDF

    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.mf4", Path(tmp) / "out.mf4"
        src.write_bytes(data)
        with MDF(src) as mdf:
            cut = mdf.cut(start=t0_s, stop=t1_s, whence=1, include_ends=False)
            cut.save(dst, overwrite=True)
            cut.close()
        return dst.read_bytes()


def mf4_decoded(mf4: bytes, dbc: bytes) -> bytes:
    """The MDF4 bus log decoded with a DBC into value channels, each with its own time
    stamps (asammdf's extract_bus_logging, as its GUI's 'DBC decode' does)."""
    from asammdf import MDF

    with tempfile.TemporaryDirectory() as tmp:
        src, db, dst = Path(tmp) / "in.mf4", Path(tmp) / "db.dbc", Path(tmp) / "out.mf4"
        src.write_bytes(mf4)
        db.write_bytes(dbc)
        with MDF(src) as mdf:
            dec = mdf.extract_bus_logging({"CAN": [(str(db), 0)]})
            dec.save(dst, overwrite=True)
            dec.close()
        return dst.read_bytes()


def can_log_as(mf4: bytes, suffix: str) -> bytes:
    """The frames of an MDF4 bus log written as a python-can log of ``suffix``
    (.asc, .blf, .trc, .log, .csv) by python-can's own writer."""
    import can

    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.mf4", Path(tmp) / f"out{suffix}"
        src.write_bytes(mf4)
        with can.LogReader(src) as reader, can.Logger(dst) as writer:
            for msg in reader:
                writer.on_message_received(msg)
        return dst.read_bytes()


# --------------------------------------------------------------------------- the list
def build(m: Mirror) -> dict[str, bytes]:
    """Every file of this folder (relative path -> bytes)."""
    out: dict[str, bytes] = {}

    def orig(dest: str, src: tuple[str, str], path: str) -> None:
        out[dest] = m.read(src, path)

    # PX4 ULogs (pyulog's test logs), cut to the IMU topics and a few seconds
    imu_topics = ["sensor_combined", "sensor_gyro", "sensor_accel", "vehicle_imu"]
    out["ulog/sample_bench_8s.ulg"] = ulog_excerpt(m.read(PYULOG, "test/sample.ulg"),
                                                    imu_topics, 10.0, 18.0)
    out["ulog/cubeorange_gyro_1hz.ulg"] = ulog_excerpt(m.read(PYULOG, "test/sample_log_small.ulg"),
                                                       imu_topics, 0.0, 1e9)
    out["ulog/sitl_alternating_steps.ulg"] = ulog_excerpt(
        m.read(PYULOG, "test/sample_logging_tagged_and_default_params.ulg"), imu_topics, 0.0, 1e9)
    out["ulog/sitl_250hz_6s.ulg"] = ulog_excerpt(m.read(PYULOG, "test/sample_px4_events.ulg"),
                                                 imu_topics, 0.0, 6.0)

    # ROS 1 bags with sensor_msgs/Imu (robot_localization's test bags), cut in time
    out["ros1/jackal_imu_50hz_20s.bag"] = rosbag1_excerpt(m.read(ROBOT_LOC, "test/test2.bag"), 0.0, 20.0)
    out["ros1/husky_imu_30hz_40s.bag"] = rosbag1_excerpt(m.read(ROBOT_LOC, "test/test1.bag"), 0.0, 40.0)

    # ROS 2 bags / MCAP as rosbag2's tests have them (no Imu; service schemas)
    orig("ros2/topics_and_services.mcap", ROSBAG2, "rosbag2_cpp/test/rosbag2_cpp/bags/topics_and_services.mcap")
    orig("ros2/talker/metadata.yaml", ROSBAG2, "rosbag2_py/test/resources/sqlite3/talker/metadata.yaml")
    orig("ros2/talker/talker.db3", ROSBAG2, "rosbag2_py/test/resources/sqlite3/talker/talker.db3")

    # CAN: CANedge MDF4 bus logs with a CANmod.gps IMU (id 9, ~100 Hz) and its DBC
    dbc = m.read(CSS, "examples/other/matlab-basics/dbc_files/canmod-gps.dbc")
    out["can/canmod-gps.dbc"] = dbc
    clean = mf4_excerpt(m.read(CSS, "examples/data-processing/LOG/94C49784/00000005/00000017-6099D010.MF4"),
                        0.0, 8.0)
    out["can/canmod_imu_8s.mf4"] = clean
    out["can/canmod_imu_bursty_35s.mf4"] = mf4_excerpt(
        m.read(CSS, "examples/data-processing/LOG/2F6913DB/00000004/00000001.MF4"), 0.0, 35.0)
    for suffix in (".asc", ".blf", ".trc", ".log", ".csv"):
        out[f"can/canmod_imu_8s{suffix}"] = can_log_as(clean, suffix)
    # the same DBC with a cycle time that contradicts the log (20 ms, the log runs at 100 Hz)
    out["can/canmod-gps_cycle20ms.dbc"] = dbc.rstrip() + (
        b'\nBA_DEF_ BO_  "GenMsgCycleTime" INT 0 65535;\nBA_DEF_DEF_  "GenMsgCycleTime" 0;'
        b'\nBA_ "GenMsgCycleTime" BO_ 9 20;\n')
    orig("can/cantools_timing.dbc", CANTOOLS, "tests/files/dbc/timing.dbc")
    orig("can/cantools_vehicle.dbc", CANTOOLS, "tests/files/dbc/vehicle.dbc")

    # MDF4 with value channels: the clean bus log decoded with its DBC by asammdf
    out["mdf/canmod_imu_decoded_8s.mf4"] = mf4_decoded(clean, dbc)

    # LAS (lasio's test files with time curves)
    orig("las/time_hhmmss_date.las", LASIO, "tests/examples/data_characters.las")
    orig("las/etim_seconds.las", LASIO, "tests/examples/2.0/sample_2.0_based.las")
    orig("las/etim_in_metres.las", LASIO, "tests/examples/skip_data_section_comments.las")

    # imu_utils Allan curves (taus in s, gyro ADEV in deg/h, accel in m/s^2) and params
    for sensor in ("16448", "A3", "xsens"):
        orig(f"imu_utils/{sensor}_imu_param.yaml", IMU_UTILS, f"data/{sensor}_imu_param.yaml")
        for kind in ("gyr", "acc", "sim_gyr", "sim_acc"):
            for ax in "txyz":
                name = f"data_{sensor}_{kind}_{ax}.txt"
                orig(f"imu_utils/{name}", IMU_UTILS, f"data/{name}")
    return out


def content(rel: str, data: bytes) -> object:
    """What --check compares: the frames of a CAN log, the channels of an MDF4 file,
    else the bytes."""
    suffix = Path(rel).suffix
    if rel.startswith(("can/", "mdf/")) and suffix != ".dbc":
        with tempfile.TemporaryDirectory() as tmp:
            f = Path(tmp) / f"f{suffix}"
            f.write_bytes(data)
            if rel.startswith("can/"):
                import can

                with can.LogReader(f) as reader:
                    return [(round(m.timestamp, 6), m.arbitration_id, bytes(m.data)) for m in reader]
            from asammdf import MDF

            with MDF(f) as mdf:
                return [(s.name, s.samples.tobytes(), s.timestamps.tobytes()) for s in mdf.iter_channels()]
    return sha256(data)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mirror", nargs="?", default="/work/.mirror")
    ap.add_argument("--out", default=str(HERE))
    ap.add_argument("--check", action="store_true", help="compare with the files here, write nothing")
    args = ap.parse_args(argv)
    files = build(Mirror(Path(args.mirror)))
    bad = 0
    for rel, data in sorted(files.items()):
        dest = Path(args.out) / rel
        if args.check:
            same = dest.is_file() and content(rel, dest.read_bytes()) == content(rel, data)
            bad += not same
            print(f"{'ok  ' if same else 'DIFF'} {rel}")
            continue
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_bytes(data)
        print(f"{len(data):>8} {sha256(data)} {rel}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
