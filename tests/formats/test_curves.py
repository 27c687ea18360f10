"""Other tools' Allan-deviation files (fogmon.formats.curves) through `fogmon fit`: imu_utils's
published results (tests/data/public/imu_utils, PROVENANCE.md) against imu_utils's own fitted
values, allan_variance_ros's allan_variance.csv as its algorithm writes it, and the checks of
the rate against the taus and the term counts (issue 30.8)."""
from __future__ import annotations

import math
import os
import re

import numpy as np
import pytest

from fogmon.cli import main
from fogmon.davar.curve import adev_from_curve
from fogmon.davar.fit import fit_noise
from fogmon.errors import FogmonError
from fogmon.formats.curves import IMU_UTILS_DPH, read_curves
from fogmon.units import G0_MPS2

IMU_UTILS = os.path.join(os.path.dirname(__file__), "..", "data", "public", "imu_utils")


def imu_utils_yaml(sensor: str) -> dict[tuple[str, str, str], float]:
    """(Gyr|Acc, x|y|z, gyr_n|gyr_w|acc_n|acc_w) -> value of imu_utils's <sensor>_imu_param.yaml."""
    out, sec, axis = {}, "", ""
    with open(os.path.join(IMU_UTILS, f"{sensor}_imu_param.yaml")) as fh:
        for line in fh:
            s = line.strip()
            if s in ("Gyr:", "Acc:"):
                sec = s[:-1]
            elif s.endswith("-axis:"):
                axis = s[0]
            elif m := re.fullmatch(r"(gyr_n|gyr_w|acc_n|acc_w): (\S+)", s):
                out[(sec, axis, m.group(1))] = float(m.group(2))
    return out


def test_imu_utils_set_is_read_from_any_of_its_files_in_fogmons_units():
    cf = read_curves(os.path.join(IMU_UTILS, "data_xsens_acc_y.txt"))
    assert cf.fmt == "imu_utils" and cf.estimator == "overlapping" and len(cf.files) == 8
    assert [(c.sensor, c.axis) for c in cf.curves] == [("gyro", a) for a in "xyz"] + [("accel", a) for a in "xyz"]
    assert cf.rate_hz == pytest.approx(1 / 0.009999989173, rel=1e-12) and cf.record_m == 2**19
    raw = np.loadtxt(os.path.join(IMU_UTILS, "data_xsens_acc_y.txt"))
    np.testing.assert_allclose(cf.curves[4].adev, raw / G0_MPS2 * 1e6, rtol=1e-15)   # m/s^2 -> micro-g
    raw = np.loadtxt(os.path.join(IMU_UTILS, "data_xsens_gyr_x.txt"))
    np.testing.assert_allclose(cf.curves[0].adev, raw * 180 / math.pi / 57.3, rtol=1e-15)   # its 57.3 deg/rad
    assert pytest.approx(0.999926344, abs=1e-9) == IMU_UTILS_DPH


@pytest.mark.parametrize("sensor", ["xsens", "16448", "A3"])
def test_fit_of_imu_utils_curves_against_imu_utils_own_fit(sensor):
    """imu_utils (the version that wrote these files) fits the five terms to log10 of the
    Allan variance by least squares and writes ``n`` = its model's ADEV at tau = 1 s and
    ``w`` = its model's smallest ADEV over the taus (rad/s with 57.3 deg/rad, m/s^2).
    fogmon's model, fitted with the sampling statistics, agrees at 1 s within 10 % and at
    the minimum within 15 % on every axis of the three sensors; fogmon's white-noise
    density N alone is below ``n`` (``n`` holds the other terms at 1 s too), by at most 25 %."""
    cf = read_curves(os.path.join(IMU_UTILS, f"data_{sensor}_gyr_t.txt"))
    want = imu_utils_yaml(sensor)
    for c in cf.curves:
        res, _ = adev_from_curve(c.tau_s, c.adev, sample_rate_hz=cf.rate_hz, n_samples=3 * cf.record_m)
        fit = fit_noise(res)
        if c.sensor == "gyro":   # deg/h -> imu_utils's rad/s (57.3 deg/rad)
            to, n, w = 1 / (IMU_UTILS_DPH * 57.3 * 3600), want[("Gyr", c.axis, "gyr_n")], want[("Gyr", c.axis, "gyr_w")]
        else:                    # micro-g -> m/s^2
            to, n, w = 1e-6 * G0_MPS2, want[("Acc", c.axis, "acc_n")], want[("Acc", c.axis, "acc_w")]
        at_1s = float(fit.model_adev_dph(np.array([1.0]))[0]) * to
        smallest = float(np.min(fit.model_adev_dph(c.tau_s))) * to
        white = 60.0 * fit.N_dpsh.value * to     # N deg/sqrt(h) = ADEV(1 s)/60 of white noise alone
        assert at_1s == pytest.approx(n, rel=0.10), (sensor, c.sensor, c.axis)
        assert smallest == pytest.approx(w, rel=0.15), (sensor, c.sensor, c.axis)
        assert 0.75 * n < white < 1.01 * n, (sensor, c.sensor, c.axis)


def test_imu_utils_taus_accept_the_nominal_rate_to_1e_5_but_not_a_wrong_one(capsys, tmp_path):
    xsens = os.path.join(IMU_UTILS, "data_xsens_acc_t.txt")      # taus are multiples of 0.009999989173 s
    out = tmp_path / "imu.yaml"
    assert main(["fit", xsens, "--rate-hz", "100", "--export", "kalibr", str(out)]) == 0
    text = capsys.readouterr().out
    assert "record 1572864 samples at 100 Hz" in text and "VRW_mpsph" in text
    yaml = out.read_text()
    acc = float(re.search(r"^accelerometer_noise_density: (\S+)", yaml, re.M).group(1))
    vrw = max(float(v) for v in re.findall(r"#   accelerometer [xyz]: VRW_mpsph (\S+)", yaml))
    assert acc == pytest.approx(vrw / 60, rel=1e-5)             # m/s^2/sqrt(Hz) = VRW / 60, the largest axis
    assert re.search(r"^update_rate: 100\.0 ", yaml, re.M) and "rostopic: /imu0" not in yaml
    assert re.search(r"^accelerometer_random_walk: \d", yaml, re.M) and re.search(r"^gyroscope_noise_density: \d",
                                                                                   yaml, re.M)
    a3 = os.path.join(IMU_UTILS, "data_A3_gyr_t.txt")             # 400 Hz nominal, 384 Hz measured
    assert main(["fit", a3, "--rate-hz", "400"]) == 2
    err = capsys.readouterr().err
    assert "data_A3_gyr_t.txt: line 5, column tau_s (gyro x): tau_s" in err    # the tau furthest off the grid
    assert "is not a whole multiple of the sample period 0.0025 s" in err and len(err.splitlines()) == 1
    assert main(["fit", a3]) == 0                                  # the rate the file gives: 1 / its first tau
    assert "at 384.0131909 Hz" in capsys.readouterr().out


def avr_csv(path, acc_mps2: np.ndarray, gyro_rps: np.ndarray, measure_rate: float) -> None:
    """allan_variance.csv as allan_variance_ros (AllanVarianceComputor::allanVariance, overlap 0)
    writes it: tau = period x 0.1 for period 1..9999, bins of int(tau x measure_rate)
    samples starting at 0, m, 2m, ... while below N - m, non-overlapping Allan deviation of
    their means; accelerometer in m/s^2, gyro in deg/s; tau with 19 digits, values with 7."""
    data = np.column_stack([acc_mps2, gyro_rps * 180 / math.pi])
    cs = np.vstack([np.zeros(6), np.cumsum(data, axis=0)])
    n = len(data)
    lines = []
    for period in range(1, 10000):
        tau = period * 0.1
        m = int(tau * measure_rate)
        starts = np.arange(0, n - m, m)
        means = (cs[starts + m] - cs[starts]) / m
        with np.errstate(invalid="ignore", divide="ignore"):
            adev = np.sqrt(np.sum(np.diff(means, axis=0) ** 2, axis=0) / (2 * (len(means) - 1)))
        lines.append(f"{tau:.19g} " + " ".join(f"{v:.7g}" for v in adev) + " \n")
    with open(path, "w") as fh:
        fh.writelines(lines)


def test_allan_variance_ros_output_is_read_and_fitted(tmp_path, capsys):
    """A 10 Hz record of 1500 s with known white noise: VRW 0.1 m/s/sqrt(h) (1.667e-3 m/s^2/
    sqrt(Hz)), N 0.5 deg/sqrt(h); the rows from tau 750 s on have no value (fewer than two
    bins), which bounds the record: 2 x 750 s."""
    fs, n = 10.0, 15_000
    rng = np.random.default_rng(21)
    acc = 0.1 / 60 * math.sqrt(fs) * rng.standard_normal((n, 3)) + [0, 0, 9.81]
    gyro = 0.5 / 60 * math.pi / 180 * math.sqrt(fs) * rng.standard_normal((n, 3))
    path = tmp_path / "allan_variance.csv"
    avr_csv(path, acc, gyro, fs)
    cf = read_curves(str(path))
    assert cf.fmt == "allan_variance_ros" and cf.estimator == "non-overlapping" and cf.no_value_tau_s == 750.0
    assert len(cf.curves) == 6 and len(cf.curves[0].tau_s) == 7499
    out = tmp_path / "imu.yaml"
    assert main(["fit", str(path), "--rate-hz", "10", "--export", "ros", str(out)]) == 0
    text = capsys.readouterr().out
    assert "record 15000 samples at 10 Hz = 1500 s" in text and "non-overlapping estimator" in text
    assert "13 of the 7499 taus shown, one per octave" in text
    for sensor, name, true in (("accel", "VRW_mpsph", 0.1), ("gyro", "N_dpsh", 0.5)):
        row = re.search(rf"^  {name} +\S+ +(.*)$", text, re.M).group(1)
        for value, lo, hi in re.findall(r"(\S+) \[(\S+), (\S+)\]", row):
            assert float(lo) - 2 * (float(hi) - float(lo)) < true < float(hi) + 2 * (float(hi) - float(lo)), (
                sensor, value, lo, hi)
    yaml = out.read_text()
    assert re.search(r"^accelerometer_noise_density: \d", yaml, re.M) and "# X Velocity Random Walk:" in yaml
    assert re.search(r"^update_rate: 10\.0 ", yaml, re.M)
    assert main(["fit", str(path), "--export", "kalibr", str(out)]) == 0     # no rate: none written, nor null
    printed = capsys.readouterr().out
    assert "update_rate left out: the sample rate was assumed, not stated" in printed
    assert not re.search(r"^update_rate", out.read_text(), re.M) and "null" not in out.read_text()
    # the console's assumed rate is the one the export names as the fit's assumption
    rate = re.search(r"assumed: sample rate (\S+) Hz \(1 / the first tau", printed).group(1)
    head = out.read_text().splitlines()[:2]
    assert head[0].endswith(f", the fit assuming {rate} Hz (1 / the first tau; --rate-hz sets it)"), head
    assert head[1] == "# sample rate not stated by the source (a fitted curve): no IMU rate is written"


def test_a_rate_that_contradicts_n_terms_is_refused_with_the_rate_they_fit(tmp_path, capsys):
    curve = tmp_path / "c.csv"
    n = 2_580_960     # a gap-free record at 100 Hz: n_terms = N - 2 m + 1
    curve.write_text("tau_s,adev_dph,n_terms\n" + "".join(f"{m / 100},{10 / math.sqrt(m)},{n - 2 * m + 1}\n"
                                                        for m in (1, 2, 4, 8)))
    assert main(["fit", str(curve), "--rate-hz", "200"]) == 2
    err = capsys.readouterr().err
    assert "--rate-hz 200 Hz contradicts n_terms" in err and "fit 100 Hz" in err and len(err.splitlines()) == 1
    assert main(["fit", str(curve), "--rate-hz", "100", "--record-s", "100"]) == 2
    err = capsys.readouterr().err         # whole numbers, every digit: not "2.58096e+06 ... the 2.58096e+06"
    assert f"{curve}: line 2, column n_terms: n_terms 2580959 at tau 0.01 s is 2570960 more than the 9999 " \
           "overlapping terms" in err
    assert main(["fit", str(curve), "--rate-hz", "100"]) == 0
    with pytest.raises(FogmonError, match="contradicts n_terms"):
        adev_from_curve([0.01, 0.02], [1.0, 0.7], sample_rate_hz=300.0, n_terms=[1000, 998])


def test_accelerometer_csv_curve_gives_ieee_1293_terms(tmp_path, capsys):
    curve = tmp_path / "acc.csv"
    # white noise of 1e-3 m/s^2/sqrt(Hz): ADEV = 1e-3 / sqrt(tau) m/s^2 -> VRW = 0.06 m/s/sqrt(h)
    curve.write_text("tau_s,adev_mps2\n" + "".join(f"{t},{1e-3 / math.sqrt(t)}\n" for t in (0.01, 0.02, 0.04, 0.08)))
    # a 60 s record: on the assumed 0.32 s (the EDFs 4-21) the other terms, free beside VRW,
    # mimic a tau^-1 slope over 4 taus and VRW is not identifiable
    assert main(["fit", str(curve), "--record-s", "60"]) == 0
    text = capsys.readouterr().out
    vrw = float(re.search(r"VRW_mpsph += (\S+) m/s/sqrt\(h\)", text).group(1))
    assert vrw == pytest.approx(0.06, rel=1e-3) and "adev_ug" in text


def test_a_bad_cell_of_an_allan_variance_ros_file_and_two_adev_columns_are_named(tmp_path, capsys):
    """An outside check (2026-12-01): a negative ADEV in an allan_variance_ros file was
    reported as a missing value with no column; a CSV with two ADEV columns got a garbled
    sentence."""
    path = tmp_path / "allan_variance.csv"
    rows = [f"{0.1 * k:.1f} 1e-3 1e-3 1e-3 1e-5 1e-5 1e-5" for k in range(1, 9)]
    rows[3] = "0.4 -0.001048849 1e-3 1e-3 1e-5 1e-5 1e-5"
    path.write_text("\n".join(rows) + "\n")
    assert main(["fit", str(path), "--rate-hz", "10"]) == 2
    err = capsys.readouterr().err
    assert "line 4, column accel_x: must be > 0" in err and "-0.001048849" in err and len(err.splitlines()) == 1
    both = tmp_path / "both.csv"
    both.write_text("tau_s,adev_dph,adev_ug\n0.1,1,1\n0.2,0.7,0.7\n")
    assert main(["fit", str(both)]) == 2
    assert "line 1: header has 2 ADEV columns (adev_dph, adev_ug), a curve file holds one" in capsys.readouterr().err


def test_an_imu_utils_set_without_one_axis_file_says_so(tmp_path, capsys):
    """An outside check (2026-12-01): without data_<name>_gyr_y.txt the set was fitted with
    five curves and no word about the sixth."""
    import shutil
    src = os.path.join(os.path.dirname(__file__), "..", "data", "public", "imu_utils")
    for f in os.listdir(src):
        if f.startswith("data_16448_") and f != "data_16448_gyr_y.txt":
            shutil.copy(os.path.join(src, f), tmp_path / f)
    assert main(["fit", str(tmp_path / "data_16448_gyr_t.txt")]) == 0
    assert "imu_utils: no data_16448_gyr_y.txt beside the tau file: that axis is not fitted" in capsys.readouterr().out
