"""Several axes in one block or recording: the one-axis views every one-axis engine takes."""
import numpy as np
import pytest

from fogmon.block import Block, axis_aux
from fogmon.errors import FogmonError
from fogmon.formats.recording import recording_from_arrays

AXES = ("x", "y", "z")


def three_axis(n=6):
    rate = np.arange(3 * n, dtype=float).reshape(n, 3)
    aux = {"temp_c": np.full(n, 20.0), "temp_c_z": np.full(n, 30.0), "temp_c_x": np.full(n, 10.0),
           "vib_g": np.zeros(n), "accel_x_g": np.ones(n)}
    return recording_from_arrays(np.arange(n) / 10, rate, aux, {"sample_rate_hz": "10"}, axes=AXES)


def test_axis_aux_shares_plain_channels_and_gives_each_axis_its_own():
    aux = three_axis().aux
    assert axis_aux(aux, AXES, "z")["temp_c"][0] == 30.0
    assert axis_aux(aux, AXES, "x")["temp_c"][0] == 10.0
    assert axis_aux(aux, AXES, "y")["temp_c"][0] == 20.0          # no temp_c_y: the shared one
    assert sorted(axis_aux(aux, AXES, "y")) == ["accel_x_g", "temp_c", "vib_g"]


def test_recording_for_axis_and_block_axis_agree():
    rec = three_axis()
    b = rec.to_block()
    assert b.axes == AXES and b.rate_dph.shape == (6, 3)
    for j, a in enumerate(AXES):
        one = rec.for_axis(a)
        assert one.axes == () and one.meta["axis"] == a
        np.testing.assert_array_equal(one.rate_dph, rec.rate_dph[:, j])
        np.testing.assert_array_equal(b.axis(a).rate_dph, one.rate_dph)
        assert sorted(b.axis(a).aux) == sorted(one.aux)
    with pytest.raises(FogmonError, match="no axis 'w'"):
        rec.for_axis("w")


def test_gaps_slices_and_concatenation_keep_the_axes():
    rec = three_axis()
    rec.t_s[3:] += 0.2                                             # two samples missing
    b = rec.to_block()
    assert len(b) == 8 and not b.valid[3:5].any() and b.valid[5:].all()
    assert Block.concat([b.slice(0, 4), b.slice(4, 8)]).axes == AXES
    with pytest.raises(ValueError, match="shape"):
        Block(b.t_s, b.rate_dph[:, 0], b.valid[:, 0], axes=AXES)


MODEL3 = """
[sensor]
sample_rate_hz = 100.0
[noise]
Q_arcsec = 0.0
B_dph = 0.02
K_dphsh = 0.0
R_dphh = 0.0
N_dpsh = 0.05
[noise.x]
[noise.y]
N_dpsh = 0.07
[noise.z]
N_dpsh = 0.09
B_dph = 0.03
[[effect]]
kind = "periodic"
axes = ["z"]
period_s = 600.0
amplitude_dph = 0.2
phase_rad = 0.0
[[effect]]
kind = "vibration_noise"
n_gain_dpsh_per_g = 0.01
"""


def test_model_axes_override_the_shared_noise_and_effects_pick_their_axes(tmp_path):
    from fogmon.sim.model import load_model, save_model

    p = tmp_path / "m.toml"
    p.write_text(MODEL3)
    m = load_model(p)
    assert m.axes == AXES
    assert m.for_axis("x").noise.N_dpsh == 0.05 and m.for_axis("y").noise.N_dpsh == 0.07
    assert (m.for_axis("z").noise.N_dpsh, m.for_axis("z").noise.B_dph) == (0.09, 0.03)
    assert [e.kind for e in m.for_axis("z").effects] == ["periodic", "vibration_noise"]
    assert [e.kind for e in m.for_axis("x").effects] == ["vibration_noise"]
    save_model(m, tmp_path / "back.toml")
    assert load_model(tmp_path / "back.toml") == m
    with pytest.raises(FogmonError, match=r"no \[noise.w\] table"):
        m.for_axis("w")


@pytest.mark.parametrize("text, message", [
    (MODEL3.replace('axes = ["z"]', 'axes = ["w"]'), "axes names 'w', which has no"),
    (MODEL3.replace('axes = ["z"]', "axes = []"), "axes must be a non-empty list"),
    (MODEL3.replace("[noise.z]\nN_dpsh", "[noise.z]\nN_dps"), r"\[noise.z\] unknown key 'N_dps'"),
    (MODEL3.replace("B_dph = 0.02\n", ""), r"\[noise.x\] missing B_dph"),
])
def test_bad_axis_tables_are_one_line_errors(tmp_path, text, message):
    from fogmon.sim.model import load_model

    p = tmp_path / "m.toml"
    p.write_text(text)
    with pytest.raises(FogmonError, match=message):
        load_model(p)
