"""The paper-method commands end to end on simulated recordings with known truth."""
import re

import numpy as np
import pytest

from fogmon.cli import main
from fogmon.recording import read_replay_log, write_replay_log
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
    fs, n = 10.0, 200_000
    rng = np.random.default_rng(1)
    t = np.arange(n) / fs
    rate = rng.normal(0, 60 * 0.01 * np.sqrt(fs), n) + 2 * np.sin(2 * np.pi * t / 5580)
    p = tmp_path / "orbit.csv"
    write_replay_log(p, t, rate, meta={"sample_rate_hz": fs})
    assert main(["inorbit", str(p)]) == 0
    out = capsys.readouterr().out
    assert "N = 0.01" in out and "3 per-cycle means" in out
    lat, v = 45.0, 15.041067 * np.sin(np.radians(45.0))
    up, down = tmp_path / "up.csv", tmp_path / "down.csv"
    write_replay_log(up, t[:36000], 1.0 + 1.0002 * v + rng.normal(0, 0.01, 36000), meta={"sample_rate_hz": fs})
    write_replay_log(down, t[:36000], 1.0 - 1.0002 * v + rng.normal(0, 0.01, 36000), meta={"sample_rate_hz": fs})
    assert main(["updown", "--up", str(up), "--down", str(down), "--lat-deg", str(lat)]) == 0
    out = capsys.readouterr().out
    bias, bias_sd = map(float, re.search(r"bias +([-+\d.]+) \+/- ([\d.e-]+) deg/h", out).groups())
    sf, sf_sd = map(float, re.search(r"scale-factor error ([-+\d.]+) \+/- ([\d.e-]+) ppm", out).groups())
    assert abs(bias - 1.0) < 4 * bias_sd and abs(sf - 200.0) < 4 * sf_sd and sf_sd < 20
