"""The fleet report's gyros (fogmon.fleet.identity, docs/batch.md "Gyros"): named by a
serial number wherever the recordings lie, else by the sensor name within its folder,
else each recording alone, or by --group-by; never by the folder alone (issue 31.6: four
unrelated recordings in one folder had become one gyro with a trend line)."""
import numpy as np

from fogmon.fleet import tasks
from fogmon.fleet.identity import gyro_identity
from fogmon.fleet.report import by_gyro
from fogmon.formats.replay_log import write_replay_log
from fogmon.pipeline import PipelineConfig
from fogmon.sources.options import SourceOptions


def test_unrelated_recordings_in_one_folder_are_separate_gyros():
    metas = [{"sensor": "navigation-grade ring-laser-gyro IMU"}, {"sensor": "fogmon sim of sim_in_orbit.toml"},
             {"sensor": "fogmon sim of sim_mwd_run.toml"}, {}]
    rows = []
    for i, m in enumerate(metas):
        gyro, named_by = gyro_identity(f"replay_logs/rec{i}.csv", m)
        rows.append({"recording": f"replay_logs/rec{i}.csv", "gyro": gyro, "axis": "-", "error": ""})
    assert len(by_gyro(rows)) == 4
    assert gyro_identity("replay_logs/rec3.csv", {}) == ("rec3.csv", "recording")
    assert gyro_identity("replay_logs/rec1.csv", metas[1]) == ("fogmon sim of sim_in_orbit.toml in replay_logs",
                                                                "sensor + folder")


def test_a_serial_number_joins_folders_and_a_sensor_type_does_not():
    assert gyro_identity("day1/run.csv", {"serial": "A17", "sensor": "DSP-1760"}) == ("A17", "serial")
    assert gyro_identity("day2/run.csv", {"serial_number": " A17 "}) == ("A17", "serial_number")
    one_type = {"sensor": "DSP-1760"}
    assert gyro_identity("day1/run.csv", one_type) != gyro_identity("day2/run.csv", one_type)


def test_group_by_a_key_the_folder_or_the_recording():
    assert gyro_identity("a/r.csv", {"rig": "R2", "serial": "A17"}, "rig") == ("R2", "rig")
    assert gyro_identity("a/r.csv", {"serial": "A17"}, "rig") == ("r.csv", "recording (no rig)")
    assert gyro_identity("a/r.csv", {"serial": "A17"}, "folder") == ("a", "folder")
    assert gyro_identity("a/r.csv", {"serial": "A17"}, "recording") == ("r.csv", "recording")


def test_the_batch_check_reads_the_header_that_names_the_gyro(tmp_path):
    t = np.arange(2000) / 10.0
    path = tmp_path / "run.csv"
    write_replay_log(path, t, np.zeros_like(t), {}, {"sample_rate_hz": "10", "serial": "SN-0042", "sensor": "FOG"})
    plan = tasks.check(str(path), SourceOptions(), PipelineConfig())
    assert not plan.error and plan.meta["serial"] == "SN-0042"
    assert gyro_identity(plan.path, plan.meta) == ("SN-0042", "serial")
