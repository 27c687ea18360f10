"""simulate / iter_simulate / `fogmon sim` / SimulatedSource / scenarios."""
from __future__ import annotations

import numpy as np
import pytest

from fogmon.cli import main as cli_main
from fogmon.errors import FogmonError
from fogmon.formats.recording import recording_from_arrays
from fogmon.formats.replay_log import read_replay_log, write_replay_log
from fogmon.sim.model import Effect, Noise, SensorModel, save_model
from fogmon.sim.scenarios import ChamberParams, MwdParams, OrbitParams, make_scenario, mwd_run, orbit, thermal_chamber
from fogmon.sim.simulate import iter_simulate, simulate
from fogmon.sources.devices.simulated import SimulatedSource

MWD = SensorModel(100.0, 0.5, Noise(N_dpsh=0.02, B_dph=0.05), [
    Effect("thermal_drift",
           {"k0_poly_dph": [0.0, 0.002], "k1_pos": 40.0, "k1_neg": 25.0, "k2_pos": 0.0, "k2_neg": 0.0}),
    Effect("vibration_noise", {"n_gain_dpsh_per_g": 0.005}),
    Effect("scale_factor", {"ppm": 30.0, "asym_ppm": 5.0}),
])


def recording_with_gaps(tmp_path):
    n = 5000
    t = np.round(np.arange(n) / 100.0, 2)
    keep = np.ones(n, bool)
    keep[1000:1050] = False
    keep[3000] = False
    rng = np.random.default_rng(0)
    aux = {"temp_c": 25 + np.cumsum(rng.normal(0, 0.001, n)), "rot_dps": np.where(t < 20, 0.0, 15.0),
           "vib_g": np.abs(rng.normal(1, 0.2, n)), "extra": rng.normal(size=n)}
    p = tmp_path / "rec.csv"
    write_replay_log(p, t[keep], rng.normal(size=n)[keep], {k: v[keep] for k, v in aux.items()},
                     {"sample_rate_hz": 100})
    return p


def test_like_copies_time_base_gaps_and_aux_exactly(tmp_path):
    rec = read_replay_log(recording_with_gaps(tmp_path))
    sim = simulate(MWD, like=rec, seed=1)
    assert np.array_equal(sim.t_s, rec.t_s)
    assert list(sim.aux) == list(rec.aux)
    for k in rec.aux:
        assert np.array_equal(sim.aux[k], rec.aux[k])
    # the gyro reads bias + 3600 rot (+ scale factor + noise)
    late = rec.t_s > 30
    assert abs(np.mean(sim.rate_dph[late] - 0.5 - 3600 * rec.aux["rot_dps"][late]) - 54000 * 32.5e-6) < 0.2
    blocks = list(iter_simulate(MWD, like=rec, seed=1, chunk_samples=1024))
    assert sum(len(b) for b in blocks) == 5000 and sum(int((~b.valid).sum()) for b in blocks) == 51


def test_cli_like_reproduces_time_base_and_aux(tmp_path):
    src = recording_with_gaps(tmp_path)
    model = tmp_path / "m.toml"
    save_model(MWD, model)
    out = tmp_path / "sim.csv"
    assert cli_main(["sim", "--model", str(model), "--out", str(out), "--like", str(src), "--seed", "3"]) == 0
    a, b = read_replay_log(src), read_replay_log(out)
    assert np.array_equal(a.t_s, b.t_s) and all(np.array_equal(a.aux[k], b.aux[k]) for k in a.aux)
    assert b.meta["seed"] == "3" and b.meta["sample_rate_hz"] == "100" and b.meta["like"] == str(src)
    assert b.meta["model"] == str(model)
    # same seed, same file
    out2 = tmp_path / "sim2.csv"
    cli_main(["sim", "--model", str(model), "--out", str(out2), "--like", str(src), "--seed", "3"])
    assert out.read_text() == out2.read_text()
    # --duration-s with --like keeps the first D seconds
    out3 = tmp_path / "sim3.csv"
    cli_main(["sim", "--model", str(model), "--out", str(out3), "--like", str(src), "--duration-s", "5"])
    assert len(read_replay_log(out3)) == 500


def test_cli_duration_and_scenario(tmp_path):
    model = tmp_path / "m.toml"
    save_model(SensorModel(50.0, 0.0, Noise(N_dpsh=0.1)), model)
    out = tmp_path / "a.csv"
    assert cli_main(["sim", "--model", str(model), "--out", str(out), "--duration-s", "10", "--seed", "1"]) == 0
    r = read_replay_log(out)
    assert len(r) == 500 and r.sample_rate_hz == 50.0 and list(r.aux) == []
    save_model(MWD, model)
    assert cli_main(["sim", "--model", str(model), "--out", str(out), "--scenario", "mwd", "--duration-s", "600",
                     "--set", "rop_mph=10", "--set", "stick_slip=true", "--seed", "2"]) == 0
    r = read_replay_log(out)
    assert len(r) == 60000 and {"temp_c", "rot_dps", "vib_g", "depth_m"} <= set(r.aux)
    assert r.meta["scenario"] == "mwd" and r.meta["scenario_set"] == "rop_mph=10 stick_slip=true"
    assert abs(r.aux["depth_m"][-1] - r.aux["depth_m"][0] - 10 * 600 / 3600) < 0.01


@pytest.mark.parametrize("argv,needle", [
    (["--duration-s", "10"], "needs the aux channel 'temp_c'"),
    (["--scenario", "mwd", "--set", "rop_mh=3"], "did you mean 'rop_mph'"),
    (["--scenario", "chamber", "--duration-s", "10"], "duration follows from its profile"),
    ([], "give --duration-s, --like RECORDING or --scenario"),
    (["--like", "/nonexistent.csv"], "no such file"),
])
def test_cli_errors_are_one_line_exit_2(tmp_path, capsys, argv, needle):
    """In-process (an unexpected exception would propagate and fail the test);
    tests/sim/test_model.py runs the same path in a subprocess."""
    model = tmp_path / "m.toml"
    save_model(MWD, model)
    assert cli_main(["sim", "--model", str(model), "--out", str(tmp_path / "o.csv"), *argv]) == 2
    err = capsys.readouterr().err
    assert err.strip().count("\n") == 0 and needle in err, err


def test_cli_missing_aux_channel_names_the_model_file(tmp_path, capsys):
    model = tmp_path / "m.toml"
    save_model(MWD, model)
    assert cli_main(["sim", "--model", str(model), "--out", str(tmp_path / "o.csv"), "--duration-s", "10"]) == 2
    assert capsys.readouterr().err == (f"fogmon sim: error: --model {model}: [[effect]] #1 (thermal_drift) needs the "
                                       f"aux channel 'temp_c', which the input lacks (have: none); simulate --like a "
                                       f"recording with that column or use a --scenario\n")
    assert not (tmp_path / "o.csv").exists()
    with pytest.raises(FogmonError, match=r"^m.toml: \[\[effect\]\] #1 \(thermal_drift\) needs the aux channel"):
        next(SimulatedSource(str(model), duration_s=10.0).blocks())


def test_simulated_source_streams_the_same_numbers():
    m = SensorModel(100.0, 0.0, Noise(N_dpsh=0.05, B_dph=0.01))
    src = SimulatedSource(m, duration_s=50.0, seed=9)
    got = np.concatenate([b.rate_dph for b in src.blocks()])
    assert np.array_equal(got, simulate(m, duration_s=50.0, seed=9).rate_dph)
    assert src.counters["samples"] == 5000 and src.sample_rate_hz == 100.0 and src.meta["seed"] == "9"


def test_simulated_source_endless_until_closed_and_paced():
    from fogmon.sources.pacing import Pacer
    src = SimulatedSource(SensorModel(100.0, 0.0, Noise(N_dpsh=0.05)), seed=1, speed=10.0)
    now, slept = [0.0], []

    def sleep(d):                         # a clock that advances only by the pacer's sleeps
        slept.append(d)
        now[0] += d

    src._pacer = Pacer(10.0, clock=lambda: now[0], sleep=sleep)
    for i, _ in enumerate(src.blocks()):
        if i == 5:
            src.close()
    assert src.counters["blocks"] == 6 and src.counters["samples"] == 6 * 100
    assert sum(slept) == pytest.approx(0.5)  # 5 blocks of 1 s recording time after the first, at 10x


def test_mwd_scenario_physics():
    p = MwdParams(duration_s=4 * 3600.0, trip_s=1800.0)
    sc = mwd_run(p, seed=1)
    t, a = sc.t_s, sc.aux
    stand_s = p.stand_length_m / p.rop_mph * 3600
    drilling = a["pumps"] > 0
    # penetration rate while drilling, constant depth during connections, tripping out at the end
    rate = np.diff(a["depth_m"]) / np.diff(t)
    assert np.allclose(rate[drilling[1:] & drilling[:-1]], p.rop_mph / 3600)
    conn = (~drilling) & (t < p.duration_s - p.trip_s)
    assert conn.any() and np.allclose(rate[conn[1:] & conn[:-1]], 0.0)
    assert np.allclose(rate[t[1:] > p.duration_s - p.trip_s + 1], -p.trip_speed_mph / 3600)
    # cooled while circulating, warms toward static when pumps stop; derivatives continuous
    static = p.surface_temp_c + p.gradient_c_per_100m * a["depth_m"] / 100
    assert abs(a["temp_c"][0] - (static[0] - p.circulation_cooling_c)) < 1e-9
    i_conn_end = np.flatnonzero(conn)[-1]
    assert a["temp_c"][i_conn_end] > a["temp_c"][np.flatnonzero(conn)[0]] + 5
    d1 = np.diff(a["temp_c"]) * p.sample_rate_hz
    assert np.max(np.abs(np.diff(d1))) < 1e-3  # no kinks: two lags
    assert np.allclose(a["rot_dps"][drilling], 6 * p.rpm) and np.all(a["rot_dps"][~drilling] == 0)
    assert 2.0 < np.median(a["vib_g"][drilling]) < 4.0 and np.median(a["vib_g"][conn]) < 0.05
    assert sc.meta["connections_s"].split()[0] == f"{stand_s:g}"


def test_stick_slip_bit_speed_between_zero_and_ratio():
    sc = mwd_run(MwdParams(duration_s=600.0, stick_slip=True), seed=1)
    rpm = sc.aux["rot_dps"] / 6
    assert rpm.min() == 0.0 and abs(rpm.max() - 2.5 * 120) < 1.0


def test_chamber_scenario_plateaus_and_ramps():
    p = ChamberParams()
    sc = thermal_chamber(p)
    air = sc.aux["chamber_c"]
    ramp = np.abs(np.diff(air)) * p.sample_rate_hz * 60
    assert np.isclose(ramp.max(), 1.0) and set(np.round(np.unique(air[1:][ramp == 0]))) >= {20.0, -40.0, 60.0}
    assert sc.t_s[-1] + 1 == pytest.approx(4 * 1800 + (60 + 100 + 40) * 60)
    assert abs(sc.aux["temp_c"][np.argmin(np.abs(sc.t_s - (1800 + 3600 + 1800 - 1)))] + 40) < 0.1


def test_orbit_scenario_period():
    p = OrbitParams()
    sc = orbit(p)
    x = sc.aux["temp_c"] - sc.aux["temp_c"].mean()
    f = np.fft.rfftfreq(len(x), 1 / p.sample_rate_hz)
    assert abs(1 / f[np.argmax(np.abs(np.fft.rfft(x))[1:]) + 1] - 5580.0) < 1.0
    assert np.allclose(sc.aux["rot_dps"], 360 / 5580)


def test_scenario_drives_simulation_with_interpolated_aux():
    sc = make_scenario("orbit", {"duration_s": "11160", "sample_rate_hz": "0.5"})
    m = SensorModel(10.0, 0.0, Noise(), [Effect("thermal_drift", {"k0_poly_dph": [0.0, 1.0], "k1_pos": 0.0,
                                                                   "k1_neg": 0.0, "k2_pos": 0.0, "k2_neg": 0.0,
                                                                   "smooth_s": 0.0})])
    rec = simulate(m, aux=sc.aux, aux_t_s=sc.t_s, seed=1)
    assert len(rec) == 111600
    assert np.allclose(rec.aux["temp_c"], np.interp(rec.t_s, sc.t_s, sc.aux["temp_c"]))
    assert np.allclose(rec.rate_dph, 3600 * rec.aux["rot_dps"] + rec.aux["temp_c"])


def test_missing_aux_for_effect_is_a_clear_error():
    with pytest.raises(FogmonError, match="vib_g"):
        simulate(MWD, aux={"temp_c": np.zeros(10), "rot_dps": np.zeros(10)})
    with pytest.raises(FogmonError, match="duration"):
        simulate(SensorModel(10.0))
    with pytest.raises(FogmonError, match="longer than the aux channels"):
        simulate(SensorModel(10.0), duration_s=2.0, aux={"temp_c": np.zeros(10)})


def test_like_at_other_rate_uses_the_recording_rate():
    rec = recording_from_arrays(np.arange(100) / 10.0, np.zeros(100), meta={"sample_rate_hz": 10})
    sim = simulate(SensorModel(100.0, 0.0, Noise(N_dpsh=1.0)), like=rec, seed=1)
    assert sim.meta["sample_rate_hz"] == "10"
    assert abs(sim.rate_dph.std() / (60 * np.sqrt(10)) - 1) < 0.2


def test_replay_of_a_model_file_streams_its_simulation(tmp_path):
    """`fogmon replay MODEL.toml --duration-s D` runs a simulation through the pipeline."""

    from fogmon.sources.open import open_replay_source
    p = tmp_path / "m.toml"
    save_model(SensorModel(100.0, 0.0, Noise(N_dpsh=0.05)), p)
    src = open_replay_source(str(p))
    assert isinstance(src, SimulatedSource) and src.n_samples is None and "m.toml" in src.name
    first = next(iter(src.blocks()))
    assert len(first) == 65536 and abs(first.rate_dph.std() / (60 * 0.05 * 10) - 1) < 0.02
