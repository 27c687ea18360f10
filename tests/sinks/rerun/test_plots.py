"""Pure helpers of the labelled Rerun plots: tick values, labelled rows, colours."""
import numpy as np

from fogmon.sinks.rerun.plots import colourise, decade_rows, nice_ticks


def test_nice_ticks_are_round_and_inside_the_range():
    np.testing.assert_array_equal(nice_ticks(-5.32, 5.32), [-4, -2, 0, 2, 4])
    np.testing.assert_array_equal(nice_ticks(-3.0, 3.0), [-3, -2, -1, 0, 1, 2, 3])
    np.testing.assert_allclose(nice_ticks(0.013, 0.07), [0.02, 0.03, 0.04, 0.05, 0.06, 0.07])


def test_decade_rows_label_one_tau_per_decade():
    tau = 0.01 * 2.0 ** np.arange(14)                  # 0.01 .. 81.92 s, octaves
    assert [round(float(tau[i]), 4) for i in decade_rows(tau)] == [0.01, 0.08, 1.28, 10.24, 81.92]
    assert decade_rows(np.array([1.0, 2.0, 4.0])) == [0, 1, 2]   # few rows: all labelled


def test_colourise_clips_to_the_end_colours_and_blackens_nan():
    rgb = colourise(np.array([[-5.0, 0.0, 1.0, 9.0, np.nan]]), 0.0, 1.0, "viridis")
    assert rgb.shape == (1, 5, 3) and rgb.dtype == np.uint8
    np.testing.assert_array_equal(rgb[0, 0], rgb[0, 1])       # below lo: the lo colour
    np.testing.assert_array_equal(rgb[0, 3], rgb[0, 2])       # above hi: the hi colour
    np.testing.assert_array_equal(rgb[0, 4], [0, 0, 0])
    assert not np.array_equal(rgb[0, 1], rgb[0, 2])


def test_colourise_gives_matplotlibs_colours_and_viridis_needs_no_matplotlib():
    import matplotlib

    from fogmon.sinks.rerun.plots import _VIRIDIS

    np.testing.assert_array_equal(
        _VIRIDIS, np.round(255 * matplotlib.colormaps["viridis"](np.arange(256))[:, :3]).astype(np.uint8))
    x = np.linspace(-1.5, 1.5, 1001)
    for cmap in ("viridis", "RdBu_r"):
        want = np.round(255 * matplotlib.colormaps[cmap](np.clip((x + 1.0) / 2.0, 0.0, 1.0))[:, :3]).astype(np.uint8)
        np.testing.assert_array_equal(colourise(x, -1.0, 1.0, cmap), want)
