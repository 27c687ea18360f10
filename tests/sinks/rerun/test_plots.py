"""Helpers of the labelled Rerun plots: tick values, rounded y ranges, labelled rows,
colours, and the marks they log (read back from an .rrd)."""
import math

import numpy as np
import pytest
from helpers.rrd import read_column

from fogmon.sinks.rerun.plots import (
    NO_DATA_COLOUR,
    colourise,
    decade_rows,
    log_stacked_labels,
    log_tau_spans,
    nice_range,
    nice_ticks,
    stacked_label_texts,
)


def test_nice_ticks_are_round_and_inside_the_range():
    np.testing.assert_array_equal(nice_ticks(-5.32, 5.32), [-4, -2, 0, 2, 4])
    np.testing.assert_array_equal(nice_ticks(-3.0, 3.0), [-3, -2, -1, 0, 1, 2, 3])
    np.testing.assert_allclose(nice_ticks(0.013, 0.07), [0.02, 0.03, 0.04, 0.05, 0.06, 0.07])


def test_decade_rows_label_one_tau_per_decade():
    tau = 0.01 * 2.0 ** np.arange(14)                  # 0.01 .. 81.92 s, octaves
    assert [round(float(tau[i]), 4) for i in decade_rows(tau)] == [0.01, 0.08, 1.28, 10.24, 81.92]
    assert decade_rows(np.array([1.0, 2.0, 4.0])) == [0, 1, 2]   # few rows: all labelled


def test_colourise_clips_to_the_end_colours_and_greys_nan():
    rgb = colourise(np.array([[-5.0, 0.0, 1.0, 9.0, np.nan]]), 0.0, 1.0, "viridis")
    assert rgb.shape == (1, 5, 3) and rgb.dtype == np.uint8
    np.testing.assert_array_equal(rgb[0, 0], rgb[0, 1])       # below lo: the lo colour
    np.testing.assert_array_equal(rgb[0, 3], rgb[0, 2])       # above hi: the hi colour
    np.testing.assert_array_equal(rgb[0, 4], NO_DATA_COLOUR)  # no value: the keyed grey, no map colour
    assert not np.array_equal(rgb[0, 1], rgb[0, 2])
    for cmap in ("viridis", "RdBu_r"):
        table = colourise(np.linspace(-1.0, 1.0, 256), -1.0, 1.0, cmap).astype(int)
        assert np.abs(table - NO_DATA_COLOUR).sum(axis=1).min() > 40


@pytest.mark.parametrize("lo, hi, want", [
    (0.0035, 0.09, (0.0, 0.1)),        # 9 steps of 0.01: too dense to label, rounded out to one of 0.1
    (1.27, 6.5, (1.0, 7.0)),           # 6 steps of 1
    (0.08, 1.78, (0.0, 2.0)),
    (0.014, 0.037, (0.01, 0.04)),
    (-460.0, 400.0, (-1000.0, 1000.0)),
    (0.05, 0.05, (0.05, 0.06)),        # one value: one step above it
])
def test_nice_range_rounds_out_to_few_powers_of_ten(lo, hi, want):
    a, b = nice_range(lo, hi)
    assert (a, b) == pytest.approx(want) and a <= lo and hi <= b
    step = 10.0 ** math.floor(math.log10(b - a) - 1e-9)
    assert round((b - a) / step) <= 10 and a / step == pytest.approx(round(a / step))


def test_stacked_labels_and_tau_spans_read_back(tmp_path):
    """A legend stacked by line breaks (one anchor, lowest label first) reads back in
    order; two tau spans at one place get their labels one under the other."""
    import rerun as rr

    path = str(tmp_path / "marks.rrd")
    rec = rr.RecordingStream("plots_test")
    rec.save(path)
    log_stacked_labels(rec, "legend", [("first", (255, 0, 0)), ("second", (0, 255, 0))], (1.0, 2.0))
    log_tau_spans(rec, "spans", [(2048.0, 2048.0, "before"), (2048.0, 2048.0, "after")], (-4, 0), (255, 210, 0))
    rec.flush()
    rec.disconnect()
    legend = read_column(path, "/legend", "Points2D:labels")[0][1]
    assert legend == ["\nsecond", "first"] and stacked_label_texts(legend) == ["first", "second"]
    boxes = read_column(path, "/spans/boxes", "LineStrips2D:strips")[0][1]
    x = np.array(boxes[0])[:, 0]
    assert x.min() < math.log10(2048.0) < x.max() and np.array(boxes[0])[:, 1].tolist() == [-4, -4, 0, 0, -4]
    assert stacked_label_texts(read_column(path, "/spans/labels", "Points2D:labels")[0][1]) == ["before", "after"]


def test_colourise_gives_matplotlibs_colours_and_viridis_needs_no_matplotlib():
    import matplotlib

    from fogmon.sinks.rerun.plots import _VIRIDIS

    np.testing.assert_array_equal(
        _VIRIDIS, np.round(255 * matplotlib.colormaps["viridis"](np.arange(256))[:, :3]).astype(np.uint8))
    x = np.linspace(-1.5, 1.5, 1001)
    for cmap in ("viridis", "RdBu_r"):
        want = np.round(255 * matplotlib.colormaps[cmap](np.clip((x + 1.0) / 2.0, 0.0, 1.0))[:, :3]).astype(np.uint8)
        np.testing.assert_array_equal(colourise(x, -1.0, 1.0, cmap), want)
