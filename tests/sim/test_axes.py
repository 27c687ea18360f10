"""Simulating several axes: per-axis models, independent noise, shared aux channels as
common causes, effects on chosen axes, scenarios and `fogmon sim` writing rate_<axis>_dph."""
from __future__ import annotations

import numpy as np
import pytest

from fogmon.cli import main as cli_main
from fogmon.davar.batch import oadev
from fogmon.davar.theory import adev_model
from fogmon.errors import FogmonError
from fogmon.formats.recording import recording_from_arrays
from fogmon.formats.replay_log import write_replay_log
from fogmon.sim.model import Effect, Noise, SensorModel, save_model, validate_effect
from fogmon.sim.scenarios import make_scenario
from fogmon.sim.simulate import iter_simulate, simulate

AXES = ("x", "y", "z")
NOISE = {"x": Noise(N_dpsh=0.05, B_dph=0.02), "y": Noise(N_dpsh=0.07, B_dph=0.02),
         "z": Noise(Q_arcsec=0.02, N_dpsh=0.09, B_dph=0.03)}
PERIODIC_Z = Effect("periodic", {"period_s": 20.0, "amplitude_dph": 5.0, "phase_rad": 0.0}, ("z",))


def imu(effects=()) -> SensorModel:
    return SensorModel(100.0, 0.0, Noise(), list(effects), axis_noise=dict(NOISE))


def test_one_axis_output_for_a_seed_is_what_it_always_was():
    """Golden numbers of a one-axis run (every term, white-level, noise and mean effects,
    aux-driven) computed before several axes existed: the one-axis streams are unchanged."""
    m = SensorModel(100.0, 0.3, Noise(Q_arcsec=0.01, N_dpsh=0.05, B_dph=0.02, K_dphsh=0.01, R_dphh=0.5), [
        validate_effect("vibration_noise", {"n_gain_dpsh_per_g": 0.02}),
        validate_effect("markov", {"tau_c_s": 3.0, "sigma_dph": 0.5}),
        validate_effect("periodic", {"period_s": 7.0, "amplitude_dph": 0.4, "phase_rad": 0.1}),
        validate_effect("thermal_drift", {"k0_poly_dph": [0.0, 0.01], "k1_pos": 30.0, "k1_neg": 20.0,
                                          "k2_pos": 0.0, "k2_neg": 0.0}),
    ])
    t = np.arange(3000) / 100.0
    rec = simulate(m, aux={"vib_g": 1 + np.sin(t), "temp_c": 20 + 0.01 * t ** 1.5}, seed=11)
    assert rec.axes == () and rec.rate_dph.shape == (3000,)
    assert rec.rate_dph[[0, 1, 777, 2999]].tolist() == GOLDEN_SAMPLES
    assert float(rec.rate_dph.sum()) == pytest.approx(GOLDEN_SUM, rel=1e-12)


#: computed with the simulator as it was before several axes (commit 9d437a7)
GOLDEN_SAMPLES = [24.361930852241763, -32.537815741326774, 19.962651007012877, 66.92633241176408]
GOLDEN_SUM = 6303.408233460001


def test_each_axis_has_its_own_ieee952_adev():
    """Per-axis ADEV (fogmon.davar.batch.oadev) against IEEE-952 theory of that axis's
    [noise.<axis>] within 6 % (EDF > 500 at every tau tested)."""
    rec = simulate(imu(), duration_s=2000.0, seed=5)
    assert rec.axes == AXES and rec.rate_dph.shape == (200000, 3)
    for j, a in enumerate(AXES):
        res = oadev(rec.rate_dph[:, j], 100.0, taus=16, alpha=0)
        sel = (res.tau_s >= 0.02) & (res.tau_s <= 2.0)
        nz = NOISE[a]
        theory = adev_model(res.tau_s[sel], nz.Q_arcsec, nz.N_dpsh, nz.B_dph)
        assert np.allclose(res.adev_dph[sel], theory, rtol=0.06), a


def test_streamed_blocks_equal_the_recording_and_axis_streams_are_seeded():
    m = imu([PERIODIC_Z])
    rec = simulate(m, duration_s=30.0, seed=3)
    blocks = list(iter_simulate(m, duration_s=30.0, seed=3, chunk_samples=700))
    assert all(b.axes == AXES and b.rate_dph.shape == (len(b), 3) and b.valid.all() for b in blocks)
    assert np.array_equal(np.concatenate([b.rate_dph for b in blocks]), rec.rate_dph)
    assert np.array_equal(simulate(m, duration_s=30.0, seed=3).rate_dph, rec.rate_dph)
    assert not np.array_equal(simulate(m, duration_s=30.0, seed=4).rate_dph, rec.rate_dph)


def test_an_effect_on_z_changes_z_only():
    """x and y bit for bit as without the effect; z differs by exactly the sinusoid."""
    plain = simulate(imu(), duration_s=100.0, seed=8)
    with_z = simulate(imu([PERIODIC_Z]), duration_s=100.0, seed=8)
    assert np.array_equal(with_z.rate_dph[:, :2], plain.rate_dph[:, :2])
    diff = with_z.rate_dph[:, 2] - plain.rate_dph[:, 2]
    assert np.allclose(diff, 5.0 * np.sin(2 * np.pi * with_z.t_s / 20.0), atol=1e-9)


def test_noise_is_independent_across_axes_while_a_shared_vibration_sets_every_level():
    """One vib_g switching between 0.1 and 3 g every 10 s drives a vibration_noise
    effect on every axis: the rates do not correlate (|r| < 4 standard deviations of r
    for independent series with this variance profile, sqrt(sum w^2) / sum w with
    w = N(t)^2), the per-second noise power of the axes follows the one vibration level
    together (r > 0.9; 0.958 or more over 20 seeds)."""
    n, sample_rate_hz = 200000, 100.0
    t = np.arange(n) / sample_rate_hz
    vib = np.where(np.floor(t / 10.0) % 2 == 0, 0.1, 3.0)
    m = SensorModel(sample_rate_hz, 0.0, Noise(N_dpsh=0.01), [Effect("vibration_noise", {"n_gain_dpsh_per_g": 0.05})],
                    axis_noise={a: Noise(N_dpsh=0.01) for a in AXES})
    rec = simulate(m, aux={"vib_g": vib}, seed=2)
    r = rec.rate_dph
    power = (r.reshape(-1, 100, 3) ** 2).mean(axis=1)           # per-second mean square, per axis
    w = (0.01 + 0.05 * vib) ** 2
    sd_r = np.sqrt(np.sum(w ** 2)) / np.sum(w)                  # ~1.4 / sqrt(n) here
    for i, j in ((0, 1), (0, 2), (1, 2)):
        assert abs(np.corrcoef(r[:, i], r[:, j])[0, 1]) < 4 * sd_r
        assert np.corrcoef(power[:, i], power[:, j])[0, 1] > 0.9
    # and the level law N = N0 + gain vib_g holds on each axis
    hi = vib == 3.0
    assert np.allclose(r[hi].std(axis=0), 60 * (0.01 + 0.05 * 3.0) * 10, rtol=0.02)


def three_axis_like(n=4000):
    """A 3-axis recording at 100 Hz: temp_c shared and flat, temp_c_z heating, a gap."""
    t = np.arange(n) / 100.0
    keep = np.ones(n, bool)
    keep[1000:1020] = False
    aux = {"temp_c": np.full(n, 20.0), "temp_c_z": 20.0 + 0.002 * t ** 2, "vib_g": np.full(n, 0.5)}
    return recording_from_arrays(t[keep], np.zeros((keep.sum(), 3)), {k: v[keep] for k, v in aux.items()},
                                 {"sample_rate_hz": "100"}, axes=AXES)


THERMAL = Effect("thermal_drift", {"k0_poly_dph": [0.0, 1.0], "k1_pos": 0.0, "k1_neg": 0.0, "k2_pos": 0.0,
                                   "k2_neg": 0.0, "smooth_s": 0.0})


def test_like_gives_the_time_base_and_each_axis_its_own_aux():
    """temp_c_z drives the thermal drift of z; x and y see the shared temp_c."""
    like = three_axis_like()
    sim = simulate(SensorModel(100.0, 0.0, Noise(), [THERMAL], axis_noise={a: Noise() for a in AXES}),
                   like=like, seed=1)
    assert np.array_equal(sim.t_s, like.t_s) and list(sim.aux) == list(like.aux)
    assert np.allclose(sim.rate_dph[:, :2], 20.0)
    assert np.allclose(sim.rate_dph[:, 2], like.aux["temp_c_z"])
    blocks = list(iter_simulate(SensorModel(100.0, 0.0, Noise(N_dpsh=0.1)), like=like, seed=1, chunk_samples=512))
    assert sum(int((~b.valid).sum()) for b in blocks) == 20 * 3 and blocks[0].axes == AXES
    # streamed in chunks, the thermal drift looks back on each axis's own temperature
    smooth = SensorModel(100.0, 0.0, Noise(), [Effect("thermal_drift", {**THERMAL.params, "smooth_s": 3.0,
                                                                        "k1_pos": 50.0, "k1_neg": 50.0})],
                         axis_noise={a: Noise() for a in AXES})
    whole = simulate(smooth, like=like, seed=1)
    streamed = np.concatenate([b.rate_dph[b.valid.all(axis=1)]
                               for b in iter_simulate(smooth, like=like, seed=1, chunk_samples=333)])
    assert np.allclose(streamed, whole.rate_dph, rtol=0, atol=1e-9)
    assert np.ptp(whole.rate_dph[:, 2] - whole.rate_dph[:, 0]) > 10.0


def test_one_axis_model_like_a_three_axis_recording_gives_every_axis_the_same_noise():
    like = three_axis_like(20000)
    sim = simulate(SensorModel(100.0, 0.0, Noise(N_dpsh=0.05)), like=like, seed=4)
    assert sim.axes == AXES
    assert np.allclose(sim.rate_dph.std(axis=0), 60 * 0.05 * 10, rtol=0.03)
    assert abs(np.corrcoef(sim.rate_dph[:, 0], sim.rate_dph[:, 1])[0, 1]) < 4 / np.sqrt(len(sim))


def test_a_scenario_with_axes_makes_a_one_axis_model_three_axis():
    sc = make_scenario("mwd", {"axes": "xyz", "duration_s": "600"}, seed=1)
    assert sc.axes == AXES and {"rot_dps_x", "rot_dps_y", "rot_dps_z", "vib_g", "temp_c"} <= set(sc.aux)
    assert "rot_dps" not in sc.aux and not sc.aux["rot_dps_x"].any() and sc.aux["rot_dps_z"].max() == 720.0
    m = SensorModel(10.0, 0.0, Noise(), [Effect("scale_factor", {"ppm": 100.0, "asym_ppm": 0.0})])
    rec = simulate(m, aux=sc.aux, aux_t_s=sc.t_s, seed=1, axes=sc.axes)
    rot_z = rec.aux["rot_dps_z"]
    assert np.allclose(rec.rate_dph[:, :2], 0.0) and np.allclose(rec.rate_dph[:, 2], 3600 * rot_z * (1 + 1e-4))
    one = make_scenario("mwd", {"duration_s": "600"}, seed=1)         # one axis: as before, same conditions
    assert one.axes == () and np.array_equal(one.aux["rot_dps"], sc.aux["rot_dps_z"])
    assert np.array_equal(one.aux["vib_g"], sc.aux["vib_g"])


def test_orbit_scenario_three_axes_and_bad_axis_parameters():
    sc = make_scenario("orbit", {"axes": "xyz", "axis_factors": "0.1,-1,0"})
    assert np.allclose(sc.aux["rot_dps_y"], -360 / 5580) and np.allclose(sc.aux["rot_dps_x"], 36 / 5580)
    with pytest.raises(FogmonError, match="one cosine per axis"):
        make_scenario("orbit", {"axes": "xy"})
    with pytest.raises(FogmonError, match="spin_axis 'z' is not one of axes"):
        make_scenario("mwd", {"axes": "xy"})
    with pytest.raises(FogmonError, match="parameter axes: bad value 'xx'"):
        make_scenario("chamber", {"axes": "xx"})


def read_csv(path):
    """(meta, header, rows as an array) of a replay log, read with numpy only."""
    lines = path.read_text().splitlines()
    meta = dict(ln[2:].split(": ", 1) for ln in lines if ln.startswith("# ") and ": " in ln)
    body = [ln for ln in lines if not ln.startswith("#")]
    return meta, body[0], np.loadtxt(body[1:], delimiter=",", ndmin=2)


def test_cli_writes_a_three_axis_replay_log(tmp_path, capsys):
    model = tmp_path / "imu.toml"
    save_model(imu([PERIODIC_Z]), model)
    out = tmp_path / "sim3.csv"
    assert cli_main(["sim", "--model", str(model), "--out", str(out), "--duration-s", "20", "--seed", "3"]) == 0
    assert "wrote 2000 samples of axes x, y, z at 100 Hz" in capsys.readouterr().out
    meta, header, data = read_csv(out)
    assert header == "time_s,rate_x_dph,rate_y_dph,rate_z_dph"
    assert meta["sample_rate_hz"] == "100" and meta["seed"] == "3" and meta["model"] == str(model)
    want = simulate(imu([PERIODIC_Z]), duration_s=20.0, seed=3)
    assert data.shape == (2000, 4)
    assert np.allclose(data[:, 1:], want.rate_dph, rtol=1e-11, atol=1e-12)


def test_cli_like_three_axis_and_axis_selects_one(tmp_path, monkeypatch):
    like = three_axis_like()
    src = tmp_path / "like3.csv"
    write_replay_log(src, like.t_s, like.rate_dph, like.aux, like.meta, axes=AXES)
    # the recording as the reader gives it (this test is about the simulator, not the reader)
    monkeypatch.setattr("fogmon.sources.open.read_recording", lambda path, opts=None: like)
    model = tmp_path / "m.toml"
    save_model(SensorModel(100.0, 0.0, Noise(N_dpsh=0.05), [THERMAL]), model)
    out, out_z = tmp_path / "s.csv", tmp_path / "z.csv"
    base = ["sim", "--model", str(model), "--like", str(src), "--seed", "6"]
    assert cli_main([*base, "--out", str(out)]) == 0
    assert cli_main([*base, "--out", str(out_z), "--axis", "z"]) == 0
    _, head, full = read_csv(out)
    assert head == "time_s,rate_x_dph,rate_y_dph,rate_z_dph,temp_c,temp_c_z,vib_g"
    meta_z, head_z, z = read_csv(out_z)
    assert meta_z["axis"] == "z" and head_z == "time_s,rate_dph,temp_c,vib_g"
    assert len(full) == len(z) == 3980 and np.array_equal(z[:, 0], full[:, 0])
    assert np.array_equal(z[:, 1], full[:, 3]) and np.array_equal(z[:, 2], full[:, 5])   # z's rate, temp_c_z
    out5 = tmp_path / "s5.csv"
    assert cli_main([*base, "--out", str(out5), "--duration-s", "5"]) == 0           # the first 5 s, all axes
    _, head5, first = read_csv(out5)
    assert head5 == head and np.array_equal(first, full[:500])


def test_cli_orbit_scenario_three_axes(tmp_path):
    """The in-orbit paper's three-axis FOG: one model, orbital rate on y, one temperature."""
    model = tmp_path / "m.toml"
    save_model(SensorModel(10.0, 0.0, Noise(N_dpsh=0.01)), model)
    out = tmp_path / "orbit.csv"
    assert cli_main(["sim", "--model", str(model), "--out", str(out), "--scenario", "orbit", "--duration-s", "600",
                     "--set", "axes=xyz", "--seed", "1"]) == 0
    meta, head, data = read_csv(out)
    assert head == "time_s,rate_x_dph,rate_y_dph,rate_z_dph,temp_c,rot_dps_x,rot_dps_y,rot_dps_z"
    assert meta["scenario"] == "orbit" and meta["scenario_set"] == "axes=xyz" and data.shape == (6000, 8)
    assert np.allclose(data[:, 1:4].mean(axis=0), [0.0, 3600 * 360 / 5580, 0.0], atol=0.1)



def test_cli_axis_must_name_an_axis_of_the_run(tmp_path, capsys):
    model = tmp_path / "pq.toml"
    save_model(SensorModel(10.0, 0.0, Noise(), axis_noise={"p": Noise(N_dpsh=0.1), "q": Noise()}), model)
    out = tmp_path / "o.csv"
    assert cli_main(["sim", "--model", str(model), "--out", str(out), "--duration-s", "5", "--axis", "x"]) == 2
    assert "--axis x: the simulation has no such axis (its axes: p, q)" in capsys.readouterr().err
    assert not out.exists()


def test_simulated_source_of_a_three_axis_model_counts_samples_not_axis_cells():
    from fogmon.sources.devices.simulated import SimulatedSource

    like = three_axis_like()
    src = SimulatedSource(SensorModel(100.0, 0.0, Noise(N_dpsh=0.05)), like=like, seed=2)
    blocks = list(src.blocks())
    assert src.axes == AXES and all(b.axes == AXES for b in blocks)
    assert src.counters["samples"] == len(like) == 3980 and src.counters["samples_missing"] == 20
    got = np.concatenate([b.rate_dph[b.valid.all(axis=1)] for b in blocks])
    assert np.array_equal(got, simulate(SensorModel(100.0, 0.0, Noise(N_dpsh=0.05)), like=like, seed=2).rate_dph)
