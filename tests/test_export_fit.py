"""`--export kalibr|matlab|ros` (fogmon.export) against hand-computed unit conversions, from
replay, explain and `fogmon fit`; `fogmon fit CURVE.csv` and fogmon.adev_from_curve equal
to fitting the record itself when the curve states its term counts; bad curve files."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

import fogmon
from fogmon.cli import main
from fogmon.davar.fit import Coefficient
from fogmon.export import kalibr_yaml, matlab_snippet, ros_yaml
from fogmon.formats.replay_log import write_replay_log


class FakeFit:
    """A whole-record fit with chosen coefficients (identifiable unless an upper limit is given)."""

    def __init__(self, **values):
        self.c = {}
        for name in ("Q_arcsec", "N_dpsh", "B_dph", "K_dphsh", "R_dphh"):
            v = values.get(name, 0.0)
            if isinstance(v, tuple):   # ("upper", limit): not identifiable
                self.c[name] = Coefficient(0.0, 0.0, v[1], False, v[1])
            else:
                self.c[name] = Coefficient(v, 0.9 * v, 1.1 * v, True, 1.2 * v)

    def coefficients(self):
        return self.c


def yaml_values(text: str) -> dict[str, str]:
    """`key: value` lines (comments cut off) of a flat YAML file."""
    out = {}
    for line in text.splitlines():
        m = re.match(r"^([A-Za-z_]+):\s*([^#]*?)\s*(#.*)?$", line)
        if m:
            out[m.group(1)] = m.group(2)
    return out


def test_kalibr_values_are_the_documented_conversions_hand_computed():
    fit = FakeFit(N_dpsh=0.1, B_dph=0.5, K_dphsh=1.0)
    v = yaml_values(kalibr_yaml(fit, "run.csv", 100.0, "/imu0"))
    # 0.1 deg/sqrt(h) = 0.1 / 60 deg/sqrt(s) = 0.1 / 60 x 0.017453292519943295 rad/sqrt(s)
    assert float(v["gyroscope_noise_density"]) == pytest.approx(2.908882086657216e-05, rel=1e-15)
    # 1 deg/h/sqrt(h) = 1 / 3600 / 60 deg/s/sqrt(s) = 0.017453292519943295 / 216000 rad/s^2/sqrt(Hz)
    assert float(v["gyroscope_random_walk"]) == pytest.approx(8.080228018492266e-08, rel=1e-15)
    assert float(v["update_rate"]) == 100.0 and v["rostopic"] == "/imu0"
    assert "accelerometer_noise_density" not in v          # a gyro recording cannot give it: left commented out
    text = kalibr_yaml(fit, "run.csv", 100.0)
    # B has no Kalibr field: said in a comment with its rad/s value (0.5 deg/h = 2.42406840554768e-06 rad/s)
    assert "bias instability B 0.5 deg/h" in text and "2.42407e-06 rad/s" in text
    # discrete per-sample sigmas at 100 Hz: density x 10 and random walk / 10
    assert "white sigma 0.000290888 rad/s" in text and "bias step sigma 8.08023e-09 rad/s" in text


def test_not_identifiable_terms_are_exported_as_their_upper_limit_and_say_so():
    fit = FakeFit(N_dpsh=0.1, K_dphsh=("upper", 2.0))
    text = kalibr_yaml(fit, "run.csv", 100.0)
    assert float(yaml_values(text)["gyroscope_random_walk"]) == pytest.approx(2.0 * math.pi / 180 / 216000, rel=1e-15)
    assert "K 2 deg/h/sqrt(h) (95 % upper limit: not identifiable from this record)" in text


def test_matlab_gyroparams_units():
    text = matlab_snippet(FakeFit(N_dpsh=0.06, B_dph=0.02, K_dphsh=0.3), "run.csv", 200.0)
    vals = dict(re.findall(r"'(\w+)', ([0-9.e+-]+)", text))
    assert float(vals["NoiseDensity"]) == pytest.approx(0.06 * 0.017453292519943295 / 60, rel=1e-15)
    assert float(vals["BiasInstability"]) == pytest.approx(0.02 * 0.017453292519943295 / 3600, rel=1e-15)
    assert float(vals["RandomWalk"]) == pytest.approx(0.3 * 0.017453292519943295 / 216000, rel=1e-15)
    assert text.count("params = gyroparams(") == 1 and "imuSensor('SampleRate', 200.0)" in text


def test_ros_output_has_allan_variance_ros_keys_and_printed_units():
    text = ros_yaml(FakeFit(N_dpsh=0.06, B_dph=0.02, K_dphsh=0.3), "run.csv", 400.0)
    v = yaml_values(text)
    assert float(v["gyroscope_noise_density"]) == pytest.approx(0.06 * math.pi / 180 / 60, rel=1e-15)
    assert float(v["update_rate"]) == 400.0
    assert "Angle Random Walk: 0.001 deg/sqrt(s) 0.06 deg/sqrt(hr)" in text
    assert "Bias Instability: 5.55556e-06 deg/s 0.02 deg/hr" in text and "0.664 B = 0.0132856 deg/hr" in text


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    sample_rate_hz, n = 100.0, 200_000
    rng = np.random.default_rng(3)
    rate = 3.0 + 60 * 0.1 * math.sqrt(sample_rate_hz) * rng.standard_normal(n)
    path = tmp_path_factory.mktemp("rec") / "run.csv"
    write_replay_log(path, np.arange(n) / sample_rate_hz, rate, meta={"sample_rate_hz": sample_rate_hz})
    return path, fogmon.oadev(rate, sample_rate_hz)


def test_replay_export_equals_its_whole_run_fit(record, tmp_path, capsys):
    path, _ = record
    out = tmp_path / "imu.yaml"
    assert main(["replay", str(path), "--no-progress", "--export", "kalibr", str(out)]) == 0
    text = capsys.readouterr().out
    n = float(re.search(r"N_dpsh\s+= ([0-9.e+-]+) deg/sqrt\(h\)", text).group(1))
    v = yaml_values(out.read_text())
    assert float(v["gyroscope_noise_density"]) == pytest.approx(n * math.pi / 180 / 60, rel=1e-3)  # 4 digits printed
    assert float(v["update_rate"]) == 100.0 and f"Wrote {out}" in text


def test_fit_of_a_curve_with_its_term_counts_equals_the_fit_of_the_record(record, tmp_path, capsys):
    _, a = record
    curve = tmp_path / "curve.csv"
    curve.write_text("# from another tool\r\ntau_s,adev_dph,n_terms\r\n" + "".join(
        f"{float(t)!r},{float(d)!r},{int(k)}\r\n" for t, d, k in zip(a.tau_s, a.adev_dph, a.n_terms, strict=True)))
    res, said = fogmon.adev_from_curve(a.tau_s, a.adev_dph, sample_rate_hz=100.0, n_terms=a.n_terms)
    assert said == [] and res.n_samples == a.n_samples
    direct, from_curve = fogmon.fit_noise(a), fogmon.fit_noise(res)
    np.testing.assert_allclose(from_curve.avar_terms, direct.avar_terms, rtol=1e-12)
    out = tmp_path / "gyro.m"
    assert main(["fit", str(curve), "--rate-hz", "100", "--export", "matlab", str(out)]) == 0
    text = capsys.readouterr().out
    assert "assumed" not in text and f"N_dpsh    = {direct.N_dpsh.value:.4g} deg/sqrt(h)" in text
    nd = float(re.search(r"'NoiseDensity', ([0-9.e+-]+)", out.read_text()).group(1))
    assert nd == pytest.approx(direct.N_dpsh.value * math.pi / 180 / 60, rel=1e-12)


def test_fit_with_stated_edf_and_without_either_says_what_it_assumed(record, tmp_path, capsys):
    _, a = record
    from fogmon.davar.confidence import edf_full
    white = edf_full(0, a.m, a.n_samples)
    res, said = fogmon.adev_from_curve(a.tau_s, a.adev_dph, sample_rate_hz=100.0, edf=white, n_samples=a.n_samples)
    np.testing.assert_allclose(res.n_terms, a.n_samples - 2 * a.m + 1, rtol=1e-12)  # white EDF = a gap-free record
    assert res.edf is not None and np.all(res.edf == white)
    curve = tmp_path / "bare.csv"
    curve.write_text("tau_s,adev_dph\n" + "".join(f"{float(t)!r},{float(d)!r}\n"
                                                  for t, d in zip(a.tau_s, a.adev_dph, strict=True)))
    assert main(["fit", str(curve)]) == 0
    text = capsys.readouterr().out
    assert "assumed: sample rate 100 Hz (1 / the first tau" in text
    assert f"assumed: record of {4 * int(a.m[-1])} samples" in text and "assumed: fully overlapping estimator" in text
    assert "N_dpsh    = " in text


@pytest.mark.parametrize("content, message", [
    ("tau_s,adev\n1,2\n2,3\n", "line 1: header has no column adev_dph"),
    ("tau_s,adev_dph\n1,2\n2,x\n", "line 3, column adev_dph: not a number: 'x'"),
    ("tau_s,adev_dph\n1,2\n1,3\n", "line 3, column tau_s: 1 is not above the previous tau"),
    ("tau_s,adev_dph,n_terms\n1,2,10\n2,3,2.5\n", "line 3, column n_terms: must be a whole number >= 1"),
    ("tau_s,adev_dph\n1,-2\n2,3\n", "line 2, column adev_dph: must be a finite number > 0"),
    ("tau_s,adev_dph\n0.01,2\n0.015,3\n", "line 3, column tau_s: tau_s 0.015 s is not a whole multiple of the "
                                          "sample period"),
    ("# c\ntau_s,adev_dph,n_terms\n0.01,2,100\n0.02,1,97\n\n0.04,1,500\n",
     "line 6, column n_terms: the sample rate 100 Hz (assumed: 1 / the first tau) contradicts n_terms"),
])
def test_bad_curve_is_one_line_naming_file_line_and_column(tmp_path, capsys, content, message):
    curve = tmp_path / "c.csv"
    curve.write_text(content)
    assert main(["fit", str(curve)]) == 2
    err = capsys.readouterr().err
    assert str(curve) in err and message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_unknown_export_format_is_one_line_before_any_work(record, tmp_path, capsys):
    path, _ = record
    assert main(["replay", str(path), "--export", "vins", str(tmp_path / "x.yaml")]) == 2
    err = capsys.readouterr().err
    assert "--export vins: unknown format (one of kalibr, matlab, ros)" in err and not (tmp_path / "x.yaml").exists()


def test_explain_exports_the_fitted_models_noise(tmp_path, capsys):
    sample_rate_hz, n = 10.0, 20_000
    rng = np.random.default_rng(4)
    rec = tmp_path / "run.csv"
    write_replay_log(rec, np.arange(n) / sample_rate_hz, 60 * 0.1 * math.sqrt(sample_rate_hz) * rng.standard_normal(n),
                     meta={"sample_rate_hz": sample_rate_hz})
    model = tmp_path / "m.toml"
    model.write_text("[sensor]\nsample_rate_hz = 10.0\n\n"
                     "[noise]\nQ_arcsec = 0.0\nN_dpsh = 0.1\nB_dph = 0.0\nK_dphsh = 0.02\nR_dphh = 0.0\n")
    out = tmp_path / "imu.yaml"
    assert main(["explain", str(rec), "--model", str(model), "--report", str(tmp_path / "r.json"), "--bootstrap", "8",
                 "--max-effects", "0", "--quiet", "--export", "kalibr", str(out)]) == 0
    v = yaml_values(out.read_text())     # no effect added: the fitted model's noise is the model's
    assert float(v["gyroscope_noise_density"]) == pytest.approx(0.1 * math.pi / 180 / 60, rel=1e-15)
    assert float(v["gyroscope_random_walk"]) == pytest.approx(0.02 * math.pi / 180 / 216000, rel=1e-15)
    assert float(v["update_rate"]) == 10.0


class FakeAccel:
    """An accelerometer's whole-record fit with chosen IEEE Std 1293 coefficients."""

    def __init__(self, **values):
        self.c = {}
        for name in ("Q_mps", "VRW_mpsph", "Bias_ug", "AccRW_mpshsh", "Ramp_mpshh"):
            v = values.get(name, 0.0)
            self.c[name] = (Coefficient(0.0, 0.0, v[1], False, v[1]) if isinstance(v, tuple) else
                            Coefficient(v, 0.9 * v, 1.1 * v, True, 1.2 * v))

    def coefficients(self):
        return self.c


def test_kalibr_accelerometer_keys_are_the_documented_conversions_hand_computed():
    acc = {"x": FakeAccel(VRW_mpsph=0.06, Bias_ug=20.0, AccRW_mpshsh=4.32),
           "y": FakeAccel(VRW_mpsph=0.09, Bias_ug=10.0, AccRW_mpshsh=("upper", 21.6))}
    text = kalibr_yaml(FakeFit(N_dpsh=0.1, K_dphsh=1.0), "imu.bag", 200.0, "/imu/data", acc)
    v = yaml_values(text)
    # VRW 0.09 m/s/sqrt(h) = 0.09 / 60 m/s^2/sqrt(Hz) (the largest axis, y);
    # AccRW 21.6 m/s/h/sqrt(h) = 1e-4 m/s^3/sqrt(Hz)
    assert float(v["accelerometer_noise_density"]) == pytest.approx(0.0015, rel=1e-15)
    assert float(v["accelerometer_random_walk"]) == pytest.approx(1e-4, rel=1e-15)
    assert "AccRW 21.6 m/s/h/sqrt(h) (95 % upper limit: not identifiable from this record)" in text
    assert "(accelerometer y, the largest of x, y)" in text
    assert "Bias 20 ug = 0.000196133 m/s^2" in text                 # 20e-6 x 9.80665
    assert "white sigma 0.0212132 m/s^2" in text                    # 0.0015 x sqrt(200)
    assert v["rostopic"] == "/imu/data" and float(v["update_rate"]) == 200.0


def test_exports_name_no_made_up_topic_or_rate():
    for writer in (kalibr_yaml, ros_yaml):
        text = writer(FakeFit(N_dpsh=0.1), "run.csv", None)          # not ROS, rate unknown
        v = yaml_values(text)
        assert "rostopic" not in v and "update_rate" not in v and "/imu0" not in text and "null" not in text
        assert "# update_rate: the record's sample rate is not known" in text


def test_ros_and_matlab_accelerometer_outputs():
    acc = {"x": FakeAccel(VRW_mpsph=0.2, Bias_ug=50.0, AccRW_mpshsh=10.0)}
    text = ros_yaml(FakeFit(N_dpsh=0.06), "run.bag", 400.0, "/imu", acc)
    assert float(yaml_values(text)["accelerometer_noise_density"]) == pytest.approx(0.2 / 60, rel=1e-15)
    assert "# X Velocity Random Walk: 0.00333333 m/s/sqrt(s) 0.2 m/s/sqrt(hr)" in text
    assert "# X Bias Instability: 0.000490332 m/s^2 6354.71 m/hr^2" in text      # 50 ug = 4.903325e-4; x 3600^2
    assert "# X Accel Random Walk: 4.62963e-05 m/s^2/sqrt(s)" in text            # 10 / 216000
    m = matlab_snippet(FakeFit(N_dpsh=0.06), "run.bag", 400.0, None, acc)
    assert "accParams = accelparams(" in m
    vals = dict(re.findall(r"'(\w+)', ([0-9.e+-]+)", m.split("accParams")[1]))
    assert float(vals["NoiseDensity"]) == pytest.approx(0.2 / 60, rel=1e-15)
    assert float(vals["BiasInstability"]) == pytest.approx(50e-6 * 9.80665, rel=1e-15)
    assert float(vals["RandomWalk"]) == pytest.approx(10 / 216000, rel=1e-15)


@pytest.mark.parametrize("fmt, mark", [("kalibr", "#"), ("matlab", "%")])
def test_a_replay_export_says_how_much_platform_motion_was_kept_out(fmt, mark, tmp_path, capsys):
    """An outside check (2026-12-01): a ROS bag 83 % in motion on axis z was exported with
    its numbers from the rest and nothing in the file said so."""
    import os
    bag = os.path.join(os.path.dirname(__file__), "data", "public", "ros1", "jackal_imu_50hz_20s.bag")
    out = tmp_path / f"imu.{fmt}"
    assert main(["replay", bag, "--axis", "z", "--export", fmt, str(out), "--rrd", str(tmp_path / "r.rrd"),
                 "--no-progress", "--quiet"]) == 0
    lines = out.read_text().splitlines()
    assert re.fullmatch(rf"{mark} platform motion kept out before the fit: \d+ samples \(\d+\.\d %\); the numbers "
                        r"describe the rest \(docs/motion\.md\)", lines[2]), lines[:3]
