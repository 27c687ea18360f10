"""`fogmon inorbit` and `fogmon thermal` axis by axis on a simulated three-axis recording:
each axis gives what the one-axis command gives on that axis alone."""
from __future__ import annotations

import argparse
import re

import numpy as np
import pytest
from helpers.doubles import Collect, ListSource

from fogmon.cli import main
from fogmon.cli.pipeline_options import add_pipeline_arguments, pipeline_config
from fogmon.errors import FogmonError
from fogmon.formats.recording import recording_from_arrays
from fogmon.formats.replay_log import read_replay_log, write_replay_log
from fogmon.methods.live_thermal import axis_thermal_effect, thermal_effect
from fogmon.methods.thermal import correct_thermal
from fogmon.pipeline import Pipeline
from fogmon.sim.model import Effect, Noise, SensorModel, load_model
from fogmon.sim.scenarios import ChamberParams, thermal_chamber
from fogmon.sim.simulate import simulate

AXES = ("x", "y", "z")
FS = 10.0
#: k1_pos (deg/h per degC/s) of each axis; z has no thermal drift
K1_POS = {"x": 30.0, "y": -12.0, "z": 0.0}


def axis_model(k1_pos: float, n_dpsh: float) -> SensorModel:
    drift = {"k0_poly_dph": [0.0, 0.004], "k1_pos": k1_pos, "k1_neg": k1_pos / 2, "k2_pos": 0.0, "k2_neg": 0.0,
             "smooth_s": 30.0, "diff_step_s": 10.0}
    effects = [Effect("thermal_drift", drift)] if k1_pos else []
    return SensorModel(FS, 0.1, Noise(N_dpsh=n_dpsh, B_dph=0.005), effects)


@pytest.fixture(scope="module")
def imu(tmp_path_factory):
    """A 3-axis chamber run (4800 s at 10 Hz): each axis simulated with its one-axis
    model; z reads its own temperature temp_c_z (5 deg C warmer)."""
    sc = thermal_chamber(ChamberParams(plateaus_c=(20.0, -20.0, 40.0), dwell_s=600.0, ramp_c_per_min=2.0))
    temps = {"x": sc.aux["temp_c"], "y": sc.aux["temp_c"], "z": sc.aux["temp_c"] + 5.0}
    sims = {a: simulate(axis_model(K1_POS[a], 0.01 * (i + 1)), aux={"temp_c": temps[a]}, aux_t_s=sc.t_s, seed=i)
            for i, a in enumerate(AXES)}
    t = sims["x"].t_s
    rate = np.column_stack([sims[a].rate_dph for a in AXES])
    rec = recording_from_arrays(t, rate, {"temp_c": sims["x"].aux["temp_c"], "temp_c_z": sims["z"].aux["temp_c"]},
                                {"sample_rate_hz": FS}, axes=AXES)
    d = tmp_path_factory.mktemp("imu")
    write_replay_log(d / "imu.csv", rec.t_s, rec.rate_dph, rec.aux, rec.meta, axes=AXES)
    for a in AXES:
        one = rec.for_axis(a)
        write_replay_log(d / f"imu_{a}.csv", one.t_s, one.rate_dph, one.aux, rec.meta)
    return d


def run(capsys, *argv):
    assert main(list(argv)) == 0
    return capsys.readouterr().out


def test_inorbit_per_axis_equals_each_axis_alone(imu, capsys):
    out = run(capsys, "inorbit", str(imu / "imu.csv"), "--period-s", "600")
    for a in AXES:
        alone = run(capsys, "inorbit", str(imu / f"imu_{a}.csv"), "--period-s", "600")
        mine = [line[len(a) + 2:] for line in out.splitlines() if line.startswith(f"{a}: ")]
        assert mine == [line.replace(f"imu_{a}.csv", "imu.csv") for line in alone.splitlines()]
    arw = [float(v) for v in re.findall(r"N = ([\d.]+) deg/sqrt\(h\)", out)]
    assert arw == pytest.approx([0.01, 0.02, 0.03], rel=0.05)       # each axis its own white noise
    only = run(capsys, "inorbit", str(imu / "imu.csv"), "--period-s", "600", "--axis", "y")
    assert [line for line in out.splitlines() if line.startswith("y: ")] == only.splitlines()
    assert main(["inorbit", str(imu / "imu.csv"), "--axis", "w"]) == 2
    assert "imu.csv: no axis 'w' (axes: x, y, z)" in capsys.readouterr().err


def test_thermal_per_axis_writes_one_effect_per_axis_and_a_corrected_log(imu, tmp_path, capsys):
    cal, corr = tmp_path / "cal.toml", tmp_path / "corr.csv"
    out = run(capsys, "thermal", str(imu / "imu.csv"), "--out-model", str(cal), "--out-corrected", str(corr))
    k1 = {a: float(re.search(rf"^{a}:   k1_pos\s+(\S+)", out, re.M).group(1)) for a in AXES}
    for a in AXES:
        assert k1[a] == pytest.approx(K1_POS[a], abs=1.5)
        alone = run(capsys, "thermal", str(imu / f"imu_{a}.csv"))
        mine = [line[len(a) + 2:] for line in out.splitlines() if line.startswith(f"{a}: ")]
        assert mine == [line.replace(f"imu_{a}.csv", "imu.csv") for line in alone.splitlines()]
    model = load_model(cal)
    effects = [e for e in model.effects if e.kind == "thermal_drift"]
    assert [e.axes for e in effects] == [("x",), ("y",), ("z",)]
    with pytest.raises(FogmonError, match="found 3"):
        thermal_effect(model, "cal.toml")                          # the one-axis loader refuses it
    assert axis_thermal_effect(model, "cal.toml", "y").params["k1_pos"] == pytest.approx(k1["y"], rel=1e-5)
    with pytest.raises(FogmonError, match=r"cal.toml: axis w: .* found 0"):
        axis_thermal_effect(model, "cal.toml", "w")
    rec, raw = read_replay_log(corr), read_replay_log(imu / "imu.csv")
    assert rec.axes == AXES and list(rec.aux) == ["temp_c", "temp_c_z"]
    for j, a in enumerate(AXES):
        assert np.std(rec.rate_dph[:, j]) < np.std(raw.rate_dph[:, j]) or K1_POS[a] == 0


def test_thermal_one_axis_picked_writes_a_one_axis_log(imu, tmp_path, capsys):
    corr, cal = tmp_path / "z.csv", tmp_path / "z.toml"
    out = run(capsys, "thermal", str(imu / "imu.csv"), "--axis", "z", "--out-corrected", str(corr),
              "--out-model", str(cal))
    assert all(line.startswith("z: ") or line.startswith("wrote") for line in out.splitlines())
    rec = read_replay_log(corr)
    assert rec.axes == () and rec.meta["axis"] == "z"
    np.testing.assert_allclose(rec.aux["temp_c"], read_replay_log(imu / "imu.csv").aux["temp_c_z"], rtol=1e-11)
    assert [e.axes for e in load_model(cal).effects] == [("z",)]


def test_thermal_axis_without_temperature_is_one_line(tmp_path, capsys):
    p = tmp_path / "r.csv"
    write_replay_log(p, np.arange(100) / 10, np.zeros((100, 2)), {"temp_c_x": np.ones(100)},
                     {"sample_rate_hz": 10}, axes=("x", "y"))
    assert main(["thermal", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "r.csv: no temp_c column for axis y (temp_c or temp_c_y)" in err


def test_live_thermal_cal_per_axis_equals_the_offline_correction(imu, tmp_path, capsys):
    """`--thermal-cal` with one thermal_drift effect per axis (what `fogmon thermal
    --out-model` writes for the three-axis run) corrects each axis live with its own
    calibration and temperature, as the offline correction does; a file that does not
    calibrate every axis of the stream is a one-line error."""
    cal, cal_xy = tmp_path / "cal.toml", tmp_path / "cal_xy.toml"
    run(capsys, "thermal", str(imu / "imu.csv"), "--out-model", str(cal))
    run(capsys, "thermal", str(imu / "imu.csv"), "--axis", "x,y", "--out-model", str(cal_xy))
    rec = read_replay_log(imu / "imu.csv")

    def live(cal_path, *more):
        p = argparse.ArgumentParser()
        add_pipeline_arguments(p)
        cfg = pipeline_config(p.parse_args(["--thermal-cal", str(cal_path), "--keep-motion", "--window-s", "600",
                                            *more]))
        n = len(rec.t_s)
        src = ListSource(rec.t_s, rec.rate_dph, [777] * (n // 777) + [n % 777], FS, aux=rec.aux, axes=AXES)
        sink = Collect()
        Pipeline(src, cfg).run([sink])
        return sink

    sink = live(cal)
    assert sink.summary.analysed == "rate_dph - thermal drift"
    model = load_model(cal)
    for j, a in enumerate(AXES):
        corrected = np.concatenate([b.aux[f"rate_corrected_dph_{a}"] for b in sink.blocks])
        temp = rec.aux["temp_c_z" if a == "z" else "temp_c"]
        offline = correct_thermal(rec.t_s, rec.rate_dph[:, j], temp, axis_thermal_effect(model, "cal.toml", a))
        assert np.max(np.abs(corrected - offline)) < 1e-8     # deg/h: the rounding of 4800 s of running sums
    with pytest.raises(FogmonError, match=r"^thermal: the calibration has a thermal_drift effect for axes x, y "
                                          r"and not for z: select calibrated axes with axis$"):
        live(cal_xy)


def test_raw_rate_with_a_thermal_calibration_says_it_is_not_applied(imu, tmp_path, capsys):
    """`--raw-rate` analyses the rate as recorded: a `--thermal-cal` given with it is not
    applied, and the run says so in one line instead of ignoring the file silently."""
    cal = tmp_path / "cal.toml"
    run(capsys, "thermal", str(imu / "imu_x.csv"), "--out-model", str(cal))
    assert main(["replay", str(imu / "imu_x.csv"), "--thermal-cal", str(cal), "--raw-rate", "--quiet",
                 "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"--thermal-cal {cal}: not applied, --raw-rate analyses the rate as recorded" in err
