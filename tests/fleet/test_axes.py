"""`fogmon batch` on a recording of several axes: one row per (recording, axis) and per
(recording, axis, window), each axis equal to the analysis of a one-axis recording of it,
whether split into chunks or not (the tasks run here without Dask)."""
import numpy as np
import pytest
from helpers.doubles import ListSource

from fogmon.cli.batch import _recording_row
from fogmon.fleet import tasks
from fogmon.fleet.chunks import plan_chunks
from fogmon.fleet.report import by_gyro
from fogmon.pipeline import OVERALL_MAX_SAMPLES, PipelineConfig
from fogmon.sources.options import SourceOptions

AXES = ("x", "y", "z")
FS = 100.0
N = 20_000
SRC, CFG = SourceOptions(), PipelineConfig(window_s=20.48, hop_s=20.48)


@pytest.fixture
def recordings(monkeypatch):
    """"three.csv" of three axes (white noise of a level per axis, a platform turn on y,
    lost samples of x) and "x.csv", "y.csv", "z.csv": its axes as one-axis recordings."""
    rng = np.random.default_rng(3)
    rate = np.array([1.0, 2.0, 3.0]) + 60 * np.array([0.05, 0.08, 0.03]) * np.sqrt(FS) * rng.standard_normal((N, 3))
    rate[10_000:10_500, 1] += 2e4 * np.sin(np.linspace(0, np.pi, 500))
    rate[15_000:15_100, 0] = np.nan
    t = np.arange(N) / FS
    sizes = [4096] * (N // 4096) + [N % 4096]

    def fake_open(path, source):
        if path == "three.csv":
            return ListSource(t, rate, sizes, FS, axes=AXES)
        return ListSource(t, rate[:, AXES.index(path[0])].copy(), sizes, FS)

    monkeypatch.setattr(tasks, "_open", fake_open)


def test_a_plan_names_the_axes_of_its_recording(recordings):
    plan = tasks.check("three.csv", SRC, CFG)
    assert not plan.error and plan.axes == AXES and plan.n_samples == N
    assert tasks.check("y.csv", SRC, CFG).axes == ()


def test_each_axis_in_chunks_equals_its_one_axis_recording(recordings):
    plan = tasks.check("three.csv", SRC, CFG)
    w = h = 2048
    chunks = plan_chunks(N, w, h, 8192, OVERALL_MAX_SAMPLES)
    assert len(chunks) >= 3
    for a in AXES:
        masked = tasks.motion_pass(plan, SRC, CFG, a)
        row, win = _recording_row(plan, a, chunks, [tasks.run_chunk(plan, c, SRC, CFG, masked, a) for c in chunks],
                                  masked)
        one = tasks.check(f"{a}.csv", SRC, CFG)
        whole = plan_chunks(N, w, h, N, OVERALL_MAX_SAMPLES)
        ref_row, ref_win = _recording_row(one, "", whole, [tasks.run_chunk(one, c, SRC, CFG) for c in whole], None)
        assert row["axis"] == a and row["error"] == "" and set(win.column("axis").to_pylist()) == {a}
        for k in ("samples", "samples_invalid", "windows", "motion_samples_excluded", "duration_s"):
            assert row[k] == ref_row[k], k
        for k, v in ref_row.items():
            if k.endswith(("_arcsec", "_dpsh", "_dph", "_dphsh", "_dphh", "_lo", "_hi")):
                assert row[k] == pytest.approx(v, rel=1e-9, abs=0), k
        assert win.num_rows == ref_win.num_rows > 0
        for name in ref_win.column_names:
            if name not in ("recording", "axis"):
                np.testing.assert_allclose(np.asarray(win.column(name), float), np.asarray(ref_win.column(name), float),
                                           rtol=1e-9, atol=0, err_msg=name)
    assert tasks.motion_pass(plan, SRC, CFG, "y").samples_excluded > 400     # the turn is y's alone
    assert tasks.motion_pass(plan, SRC, CFG, "x").samples_excluded == 0


def test_the_fleet_report_follows_each_axis_of_a_gyro():
    rows = [{"recording": f"rig/g1/run{i}.csv", "axis": a, "error": ""} for i in (1, 2) for a in AXES]
    rows += [{"recording": "rig/g2/run1.csv", "axis": "-", "error": ""}]
    groups = by_gyro(rows)
    assert sorted(groups) == ["g1 axis x", "g1 axis y", "g1 axis z", "g2"]
    assert [r["recording"] for r in groups["g1 axis y"]] == ["rig/g1/run1.csv", "rig/g1/run2.csv"]
