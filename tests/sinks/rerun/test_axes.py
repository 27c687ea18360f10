"""The Rerun sink with several axes: every axis's data under ``axis/<name>/`` in the .rrd,
read back equal to what fogmon's engine computed per axis, and a blueprint that overlays
the axes (one colour each) and puts their heatmaps side by side."""
from __future__ import annotations

import numpy as np
import pytest
from helpers.rrd import read_column, read_scalars, read_texts, read_views, rgb

from fogmon.block import Block, Event
from fogmon.davar.batch import dadev
from fogmon.davar.fit import fit_noise
from fogmon.davar.streaming import StreamingDadev
from fogmon.sinks.base import COEFFICIENTS, StreamInfo, Summary
from fogmon.sinks.rerun.plots import nice_range, stacked_label_texts
from fogmon.sinks.rerun.sink import RerunSink
from fogmon.sinks.rerun.style import AXIS_COLOURS

AXES = ("x", "y", "z")
N_DPSH = {"x": 0.05, "y": 0.1, "z": 0.2}          # white noise per axis, deg/sqrt(h)
SAMPLE_RATE_HZ, WINDOW_S, HOP_S, N = 10.0, 51.2, 12.8, 6000
BAND_DPH = (0.5, 1.0, 2.0)                      # a made-up --model band: lo, median, hi = these x N's ADEV


@pytest.fixture(scope="module")
def three_axis_rrd(tmp_path_factory):
    """A 3-axis stream driven through RerunSink as the pipeline would: blocks with 2-D
    rates (axis y loses 20 samples), per axis a StreamingDadev, its fit and ``frames``."""
    rng = np.random.default_rng(14)
    t = 2.0 + np.arange(N) / SAMPLE_RATE_HZ
    rate = 3.0 + np.column_stack([60 * N_DPSH[a] * np.sqrt(SAMPLE_RATE_HZ) * rng.standard_normal(N) for a in AXES])
    rate[3000:3020, 1] = np.nan
    temp = 25 + 0.001 * np.arange(N)
    engines = {a: StreamingDadev(SAMPLE_RATE_HZ, WINDOW_S, hop_s=HOP_S) for a in AXES}
    tau = engines["x"].m / SAMPLE_RATE_HZ
    bands = {a: tuple(f * 60 * N_DPSH[a] / np.sqrt(tau) for f in BAND_DPH) for a in AXES}
    path = str(tmp_path_factory.mktemp("rrd3") / "three.rrd")
    sink = RerunSink(rrd_path=path)
    sink.start(StreamInfo("three-axis test", SAMPLE_RATE_HZ, WINDOW_S, HOP_S, tau, ("temp_c",), model_bands=bands,
                          model_alpha=0.01, axes=AXES))
    frames: dict[str, list] = {a: [] for a in AXES}
    for k in range(0, N, 1000):
        sl = slice(k, k + 1000)
        ev = [Event(t[k] + 1.0, "gap", f"test gap {k}")] if k == 2000 else []
        block = Block.make(t[sl], rate[sl], aux={"temp_c": temp[sl]}, events=ev, axes=AXES)
        sink.block(block)
        sink.events(block.events)
        for a in AXES:
            res = engines[a].push(block.axis(a).rate_dph, block.axis(a).valid)
            if len(res):
                fit = fit_noise(res)
                t_end = t[0] + np.asarray(res.end_index, dtype=np.float64) / SAMPLE_RATE_HZ
                sink.frames(res, fit, t_end, axis=a)
                frames[a].append((res, fit, t_end))
    sink.events([Event(500.0, "coef_jump", "N_dpsh x2.0 (test)", axis="y")])
    sink.finish(Summary("three-axis test", SAMPLE_RATE_HZ, WINDOW_S, HOP_S))
    return path, t, rate, temp, tau, bands, frames


def _cat(frames, get):
    return np.concatenate([np.atleast_1d(get(d, f, te)) for d, f, te in frames], axis=0)


def test_each_axis_raw_rate_under_its_own_path(three_axis_rrd):
    path, t, rate, temp, *_ = three_axis_rrd
    for j, a in enumerate(AXES):
        tr, r = read_scalars(path, f"/axis/{a}/rate/rate_dph")
        ok = np.isfinite(rate[:, j])
        assert len(tr) == ok.sum() == (N - 20 if a == "y" else N)      # y's lost samples are not drawn
        np.testing.assert_allclose(tr, t[ok], atol=1e-9)
        np.testing.assert_array_equal(r[:, 0], rate[ok, j])
    assert len(read_scalars(path, "/rate/rate_dph")[0]) == 0             # no one-axis path
    np.testing.assert_array_equal(read_scalars(path, "/aux/temp_c")[1][:, 0], temp)


def test_each_axis_dadev_and_coefficients_equal_its_engine(three_axis_rrd):
    path, t, rate, _, _, _, frames = three_axis_rrd
    for j, a in enumerate(AXES):
        fr = frames[a]
        adev, t_end = _cat(fr, lambda d, f, te: d.adev_dph), _cat(fr, lambda d, f, te: te)
        ts, logadev = read_scalars(path, f"/axis/{a}/dadev/log10_adev_dph")
        np.testing.assert_allclose(ts, t_end, atol=1e-9)
        np.testing.assert_allclose(10.0 ** logadev, adev, rtol=1e-14)
        ref = dadev(rate[:, j], SAMPLE_RATE_HZ, WINDOW_S, HOP_S, valid=np.isfinite(rate[:, j]), t0_s=t[0])
        np.testing.assert_allclose(adev, ref.adev_dph, rtol=1e-9)        # the batch DADEV agrees
        for name in COEFFICIENTS:
            v, lo, hi, ok = (_cat(fr, lambda d, f, te, a_=attr, n=name: np.asarray(getattr(getattr(f, n), a_)))
                             for attr in ("value", "lo", "hi", "identifiable"))
            ok = ok.astype(bool) & np.isfinite(v) & np.isfinite(lo) & np.isfinite(hi)
            tc, vals = read_scalars(path, f"/axis/{a}/coef/{name}")
            assert len(tc) == int(ok.sum())
            if ok.any():
                np.testing.assert_array_equal(vals, np.column_stack([v[ok], lo[ok], hi[ok]]))
        # white noise of N_DPSH[a]: the logged N of every window is that axis's (theory, not swapped)
        _, n_vals = read_scalars(path, f"/axis/{a}/coef/N_dpsh")
        assert len(n_vals) == len(t_end)
        assert np.median(n_vals[:, 0]) == pytest.approx(N_DPSH[a], rel=0.1)
    assert len(read_scalars(path, "/coef/N_dpsh")[0]) == 0


def test_each_axis_curve_heatmap_band_and_events(three_axis_rrd):
    path, _, _, _, tau, bands, frames = three_axis_rrd
    for k, a in enumerate(AXES):
        d, _, te = frames[a][-1]
        rows = read_column(path, f"/axis/{a}/adev_curve/log10/adev_dph", "LineStrips2D:strips")
        t_last, strips = max(rows, key=lambda r: r[0])
        assert t_last == pytest.approx(te[-1], abs=1e-9)
        np.testing.assert_allclose(np.array(strips[0]), np.column_stack([np.log10(tau), np.log10(d.adev_dph[-1])]),
                                   rtol=1e-6)
        colours = read_column(path, f"/axis/{a}/adev_curve/log10/adev_dph", "LineStrips2D:colors")
        assert rgb(colours[-1][1][0]) == AXIS_COLOURS[k]
        (band,) = read_column(path, f"/axis/{a}/adev_curve/log10/model_band", "LineStrips2D:strips")
        assert band[0] is None                                            # static
        for line, ref in zip(band[1], bands[a], strict=True):
            np.testing.assert_allclose(np.array(line)[:, 1], np.log10(ref), rtol=1e-6)
        n_windows = sum(len(x[2]) for x in frames[a])
        image = read_column(path, f"/axis/{a}/dadev/heatmap/map/image", "Image:format")[-1][1][0]
        assert (image["width"], image["height"]) == (n_windows, len(tau))
        bars = read_column(path, f"/axis/{a}/adev_curve/log10/model_band/bars", "LineStrips2D:strips")[0][1]
        assert len(bars) == len(tau)                                      # one bar per tau, lo to hi
        np.testing.assert_allclose(np.array(bars)[:, :, 1], np.log10(np.column_stack([bands[a][0], bands[a][2]])),
                                   rtol=1e-6)
    legend = read_column(path, "/adev_curve/log10/legend", "Points2D:labels")[0][1]
    assert stacked_label_texts(legend) == ["axis x: measured ADEV", "axis y: measured ADEV", "axis z: measured ADEV",
                                           "darker: 68.3 % bounds", "lighter: IEEE-952 model", "greyed: --model band"]
    assert read_column(path, "/adev_curve/log10/grid", "LineStrips2D:strips")      # one shared decade grid
    assert read_texts(path, "/axis/y/events") == ["500.00 s  axis y: coef_jump: N_dpsh x2.0 (test)"]
    assert read_texts(path, "/events") == ["203.00 s  gap: test gap 2000"]       # t[2000] + 1 s


def test_blueprint_overlays_the_axes_and_sets_heatmaps_side_by_side(three_axis_rrd):
    path = three_axis_rrd[0]
    views = read_views(path)
    curve = views["Current window: ADEV (deg/h) vs tau (s), log-log"]
    assert curve["class"] == "2D" and curve["origin"] == "/"
    assert curve["contents"] == ["/adev_curve/**", "/axis/x/adev_curve/**", "/axis/y/adev_curve/**",
                                 "/axis/z/adev_curve/**"]
    assert views["Rate (deg/h) of axes x, y, z over recording time (s)"]["contents"] == [
        f"/axis/{a}/rate/rate_dph/**" for a in AXES]
    for name, unit in COEFFICIENTS.items():
        v = views[f"{name} ({unit}): x red, y green, z blue; \u25bc upper limit"]
        assert v["class"] == "TimeSeries" and v["contents"] == [f"/axis/{a}/coef/{name}/**" for a in AXES]
    heatmaps = sorted((n, v["origin"]) for n, v in views.items() if "DADEV heatmap" in n)
    assert heatmaps == [(f"{a}: DADEV heatmap", f"/axis/{a}/dadev/heatmap") for a in AXES]
    assert views["Events (all axes)"]["contents"] == ["/events", *(f"/axis/{a}/events/**" for a in AXES)]
    # one colour per axis in every view: rate, coefficient tracks, ADEV curve (above)
    for k, a in enumerate(AXES):
        for ent, col in ((f"/axis/{a}/rate/rate_dph", "SeriesLines:colors"),
                         (f"/axis/{a}/coef/B_dph", "SeriesLines:colors"),
                         (f"/axis/{a}/coef/B_dph/upper_limit", "SeriesPoints:colors")):
            assert {rgb(c) for c in read_column(path, ent, col)[0][1]} == {AXIS_COLOURS[k]}
        assert read_column(path, f"/axis/{a}/coef/B_dph", "SeriesLines:names")[0][1] == [
            f"{a}: B_dph (deg/h)", f"{a}: lo", f"{a}: hi"]


def test_coefficient_views_share_one_rounded_y_range_over_the_axes(three_axis_rrd):
    """The axes' tracks of a coefficient share a view, so each axis's ``y_range`` is the
    rounded range of all axes drawn so far: together nice, not a union of per-axis ranges."""
    path = three_axis_rrd[0]
    for name in COEFFICIENTS:
        drawn = np.concatenate([np.r_[read_scalars(path, f"/axis/{a}/coef/{name}")[1].ravel(),
                                      read_scalars(path, f"/axis/{a}/coef/{name}/upper_limit")[1].ravel()]
                                for a in AXES])
        last = [read_scalars(path, f"/axis/{a}/coef/{name}/y_range")[1][-1] for a in AXES]
        lo, hi = min(r[0] for r in last), max(r[1] for r in last)
        assert (lo, hi) == pytest.approx(nice_range(drawn.min(), drawn.max()))
