"""Several axes in one block or recording: the one-axis views every one-axis engine takes."""
import numpy as np
import pytest

from fogmon.block import Block, axis_aux
from fogmon.errors import FogmonError
from fogmon.recording import recording_from_arrays

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
