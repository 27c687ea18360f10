"""The paper-method commands end to end on simulated recordings with known truth."""
import re

import numpy as np
import pytest

from fogmon.cli import main
from fogmon.formats.replay_log import read_replay_log, write_replay_log
from fogmon.sim.model import load_model


@pytest.fixture(scope="module")
def chamber(tmp_path_factory):
    d = tmp_path_factory.mktemp("chamber")
    out = d / "chamber.csv"
    assert main(["sim", "--model", "fogmon/data/example_chamber_model.toml", "--scenario", "chamber",
                 "--out", str(out), "--seed", "4"]) == 0
    return out


def test_thermal_calibrates_writes_model_and_corrects(chamber, tmp_path, capsys):
    model, corr = tmp_path / "cal.toml", tmp_path / "corr.csv"
    rc = main(["thermal", str(chamber), "--model", "fogmon/data/example_chamber_model.toml",
               "--out-model", str(model), "--out-corrected", str(corr)])
    assert rc == 0
    out = capsys.readouterr().out
    before, after = map(float, re.search(r"averages: ([\d.]+) deg/h -> ([\d.]+) deg/h", out).groups())
    assert after < before / 4
    eff = [e for e in load_model(model).effects if e.kind == "thermal_drift"]
    assert len(eff) == 1 and eff[0].params["smooth_s"] == 30.0  # taken from --model
    assert abs(eff[0].params["k1_pos"] - 30.0) < 1.5  # truth in example_chamber_model.toml
    rec = read_replay_log(corr)
    assert len(rec) == len(read_replay_log(chamber))


def test_thermal_without_temperature_is_one_line_error(tmp_path, capsys):
    p = tmp_path / "r.csv"
    write_replay_log(p, np.arange(100) / 10, np.zeros(100), meta={"sample_rate_hz": 10})
    assert main(["thermal", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no temp_c column" in err


def test_inorbit_and_updown(tmp_path, capsys):
    sample_rate_hz, n = 10.0, 200_000
    rng = np.random.default_rng(1)
    t = np.arange(n) / sample_rate_hz
    rate = rng.normal(0, 60 * 0.01 * np.sqrt(sample_rate_hz), n) + 2 * np.sin(2 * np.pi * t / 5580)
    p = tmp_path / "orbit.csv"
    write_replay_log(p, t, rate, meta={"sample_rate_hz": sample_rate_hz})
    assert main(["inorbit", str(p)]) == 0
    out = capsys.readouterr().out
    assert "N = 0.01" in out and "3 per-cycle means" in out
    stuck = tmp_path / "stuck.csv"            # a stuck output: refused, not N = 0 and NaN bands
    write_replay_log(stuck, t[:1000], np.full(1000, 5.0), meta={"sample_rate_hz": sample_rate_hz})
    assert main(["inorbit", str(stuck)]) == 2
    assert capsys.readouterr().err.strip().endswith("stuck.csv: the rate is 5 deg/h at every one of its 1000 "
                                                    "samples: a stuck or saturated output has no noise to analyse")
    lat, v = 45.0, 15.041067 * np.sin(np.radians(45.0))
    up, down = tmp_path / "up.csv", tmp_path / "down.csv"
    write_replay_log(
        up, t[:36000], 1.0 + 1.0002 * v + rng.normal(0, 0.01, 36000), meta={"sample_rate_hz": sample_rate_hz}
    )
    write_replay_log(
        down, t[:36000], 1.0 - 1.0002 * v + rng.normal(0, 0.01, 36000), meta={"sample_rate_hz": sample_rate_hz}
    )
    assert main(["updown", "--up", str(up), "--down", str(down), "--lat-deg", str(lat)]) == 0
    out = capsys.readouterr().out
    bias, bias_sd = map(float, re.search(r"bias +([-+\d.]+) \+/- ([\d.e-]+) deg/h \(1 sigma\)$", out,
                                         re.M).groups())
    sf, sf_sd = map(float, re.search(r"scale-factor error ([-+\d.]+) \+/- ([\d.e+-]+) ppm \(1 sigma\)$", out,
                                     re.M).groups())
    assert abs(bias - 1.0) < 4 * bias_sd and abs(sf - 200.0) < 4 * sf_sd and sf_sd < 20


@pytest.fixture(scope="module")
def updown(tmp_path_factory):
    """1 h up and down at 10 Hz, latitude 45 deg: bias 1 deg/h, scale-factor error +200 ppm."""
    d = tmp_path_factory.mktemp("updown")
    sample_rate_hz, n = 10.0, 36000
    t = np.arange(n) / sample_rate_hz
    v = 15.041067 * np.sin(np.radians(45.0))
    rng = np.random.default_rng(2)
    for name, sign in (("up", 1), ("down", -1)):
        write_replay_log(d / f"{name}.csv", t, 1.0 + sign * 1.0002 * v + rng.normal(0, 0.01, n),
                         meta={"sample_rate_hz": sample_rate_hz})
    return d / "up.csv", d / "down.csv"


@pytest.mark.parametrize("swap, lat, message", [
    (True, "45", "--up {up} and --down {down} look swapped (or the latitude's sign is wrong: south is negative): "
                 "up - down = -21.28 deg/h where a gyro within 50 % of its scale factor reads +21.27 deg/h "
                 "(2 x the vertical Earth rate at latitude 45 deg)"),
    (False, "-45", "--up {up} and --down {down} look swapped (or the latitude's sign is wrong"),
    (False, "10", "--up {up} and --down {down} differ by far more than Earth rate (a wrong latitude? rates not in "
                  "deg/h?): up - down = +21.28 deg/h where a gyro within 50 % of its scale factor reads +5.224 deg/h"),
    (False, "0", "at latitude 0 deg (the equator) Earth rate has no vertical component: no scale factor can be "
                 "calibrated up/down there"),
    (False, "0.0001", "at latitude 0.0001 deg the vertical Earth rate is 2.63e-05 deg/h, too small against the "),
])
def test_updown_refuses_what_cannot_be_a_scale_factor(updown, capsys, swap, lat, message):
    up, down = updown[::-1] if swap else updown
    assert main(["updown", "--up", str(up), "--down", str(down), "--lat-deg", lat]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err.startswith("fogmon updown: error: " + message.format(up=up, down=down))
    assert cap.err.count("\n") == 1


@pytest.mark.parametrize("lat", ["95", "-90.5", "nan", "inf", "north"])
def test_updown_latitude_out_of_range_is_a_usage_error(updown, capsys, lat):
    with pytest.raises(SystemExit) as e:
        main(["updown", "--up", str(updown[0]), "--down", str(updown[1]), "--lat-deg", lat])
    assert e.value.code == 2
    assert capsys.readouterr().err == (f"fogmon updown: error: argument --lat-deg: must be a finite number in "
                                       f"-90..90, got '{lat}' (see fogmon updown --help)\n")


def test_updown_same_file_twice(updown, capsys):
    assert main(["updown", "--up", str(updown[0]), "--down", str(updown[0]), "--lat-deg", "45"]) == 2
    assert capsys.readouterr().err == (f"fogmon updown: error: --up {updown[0]} and --down {updown[0]} "
                                       f"are the same file\n")


@pytest.mark.parametrize("argv, message", [
    (["--degree", "50"], "argument --degree: must be an integer in 0..6, got '50'"),
    (["--smooth-s", "nan"], "argument --smooth-s: must be a finite number >= 0, got 'nan'"),
    (["--diff-step-s", "0"], "argument --diff-step-s: must be a finite number > 0, got '0'"),
    (["--average-s", "-5"], "argument --average-s: must be a finite number > 0, got '-5'"),
])
def test_thermal_bad_values_are_usage_errors(chamber, capsys, argv, message):
    with pytest.raises(SystemExit) as e:
        main(["thermal", str(chamber), *argv])
    assert e.value.code == 2
    assert capsys.readouterr().err == f"fogmon thermal: error: {message} (see fogmon thermal --help)\n"


@pytest.mark.parametrize("argv, message", [
    (["--average-s", "1e9"], "--average-s 1e+09 s: the peak-to-peak drift needs at least two blocks in the "
                             "19200 s of chamber.csv"),
    (["--diff-step-s", "1e9"], "2 x --diff-step-s 1e+09 = 2e+09 s of filter settling leaves less "
                               "than half of the 19200 s of chamber.csv to fit"),
    (["--out-model", "{tmp}/no/cal.toml"], "--out-model {tmp}/no/cal.toml: folder {tmp}/no does not exist"),
    (["--out-corrected", "{tmp}"], "--out-corrected {tmp}: is a folder, give a file name"),
    (["--out-corrected", "{chamber}"], "--out-corrected {chamber}: is the input {chamber}; write to another file"),
])
def test_thermal_values_and_outputs_that_cannot_work(chamber, tmp_path, capsys, argv, message):
    argv = [a.format(tmp=tmp_path, chamber=chamber) for a in argv]
    assert main(["thermal", str(chamber), *argv]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == f"fogmon thermal: error: {message.format(tmp=tmp_path, chamber=chamber)}\n"
    assert list(tmp_path.iterdir()) == []


def test_thermal_says_when_the_fit_does_not_reduce_the_drift(tmp_path, capsys):
    sample_rate_hz, n = 1.0, 20_000
    t = np.arange(n) / sample_rate_hz
    rng = np.random.default_rng(7)
    p = tmp_path / "flat.csv"          # a temperature ramp the rate does not follow, plus slow rate wander
    write_replay_log(p, t, np.cumsum(rng.normal(0, 0.05, n)), {"temp_c": 20 + 10 * np.sin(t / 3000)},
                     meta={"sample_rate_hz": sample_rate_hz})
    assert main(["thermal", str(p)]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("peak-to-peak"))
    before, after = map(float, re.search(r"averages: ([\d.]+) deg/h -> ([\d.]+) deg/h", line).groups())
    assert line.endswith(f"({before / after:.1f}x smaller)" if after < before else
                         f"({after / before:.1f}x larger: the fit does not reduce this drift)")


@pytest.mark.parametrize("argv, message", [
    (["--period-s", "0"], "fogmon inorbit: error: argument --period-s: must be a finite number > 0, got '0'"),
    (["--period-s", "nan"], "fogmon inorbit: error: argument --period-s: must be a finite number > 0, got 'nan'"),
    (["--pauta-k", "1.7"], "fogmon inorbit: error: argument --pauta-k: must be a finite number > 1.73205, got '1.7'"),
    (["--pauta-k", "inf"], "fogmon inorbit: error: argument --pauta-k: must be a finite number > 1.73205, got 'inf'"),
])
def test_inorbit_bad_values_are_usage_errors(updown, capsys, argv, message):
    with pytest.raises(SystemExit) as e:
        main(["inorbit", str(updown[0]), *argv])
    assert e.value.code == 2
    assert capsys.readouterr().err == f"{message} (see fogmon inorbit --help)\n"


def test_inorbit_period_shorter_than_two_samples(updown, capsys):
    assert main(["inorbit", str(updown[0]), "--period-s", "0.15"]) == 2
    assert capsys.readouterr().err == "fogmon inorbit: error: --period-s 0.15 s is shorter than 2 samples at 10 Hz\n"


def _short(tmp_path, n=3):
    p = tmp_path / "short.csv"
    write_replay_log(p, np.arange(n) / 10.0, np.random.default_rng(3).normal(0, 1, n), meta={"sample_rate_hz": 10})
    return p


def test_inorbit_too_short_a_recording_names_the_file(tmp_path, capsys):
    p = _short(tmp_path)
    assert main(["inorbit", str(p)]) == 2
    assert capsys.readouterr().err == (f"fogmon inorbit: error: {p}: 3 samples are too few for the in-orbit "
                                       f"evaluation (the angle random walk from first differences needs >= 100)\n")
    assert main(["inorbit", str(_short(tmp_path, 150))]) == 0     # long enough: no function names in its notes
    assert ("  bias instability: not available (the record holds 0 complete 5580 s cycles (--period-s); need >= 2)"
            in capsys.readouterr().out.splitlines())


@pytest.mark.parametrize("option", ["--up", "--down"])
def test_updown_too_short_a_recording_names_the_option_and_file(updown, tmp_path, capsys, option):
    p = _short(tmp_path)
    files = {"--up": str(updown[0]), "--down": str(updown[1]), option: str(p)}
    assert main(["updown", *[a for kv in files.items() for a in kv], "--lat-deg", "45"]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == (f"fogmon updown: error: {option} {p}: 3 samples are too few for the "
                                         f"uncertainty of its mean (an Allan deviation needs at least 4)\n")


def test_updown_off_grid_sample_names_its_line(updown, tmp_path, capsys):
    lines = updown[0].read_text().splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if ln[0].isdigit()) + 500   # the 501st data row
    t, rest = lines[k].split(",", 1)
    lines[k] = f"{float(t) + 0.05!r},{rest}"                               # half a period off the 10 Hz grid
    p = tmp_path / "up.csv"
    p.write_text("".join(lines))
    assert main(["updown", "--up", str(p), "--down", str(updown[1]), "--lat-deg", "45"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"fogmon updown: error: up.csv: line {k + 1}, column time_s: sample at time_s=") and \
        "0.50 sample periods off the 10 Hz grid" in err and err.count("\n") == 1


@pytest.mark.parametrize("name", ["corr.txt", "corr"])
def test_thermal_out_corrected_suffix_is_checked_first(chamber, tmp_path, capsys, name):
    out = tmp_path / name
    assert main(["thermal", str(chamber), "--out-corrected", str(out)]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == (f"fogmon thermal: error: --out-corrected {out}: name it .csv (replay log) "
                                         f"or .parquet (Parquet replay log); fogmon writes no other format\n")
    assert list(tmp_path.iterdir()) == []


def test_thermal_out_corrected_parquet_is_a_parquet_replay_log(chamber, tmp_path, capsys):
    csv, pq = tmp_path / "corr.csv", tmp_path / "corr.parquet"
    assert main(["thermal", str(chamber), "--out-corrected", str(csv)]) == 0
    assert main(["thermal", str(chamber), "--out-corrected", str(pq)]) == 0
    a, b = read_replay_log(csv), read_replay_log(pq)
    assert pq.read_bytes()[:4] == b"PAR1" and b.meta["corrected"] == a.meta["corrected"]
    np.testing.assert_allclose(b.rate_dph, a.rate_dph, rtol=1e-11)   # the CSV keeps 12 digits
    np.testing.assert_array_equal(b.aux["temp_c"], read_replay_log(chamber).aux["temp_c"])
