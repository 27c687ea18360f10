"""`fogmon batch` with accelerometers: accel_windows.parquet and accel_recordings.parquet
equal to `fogmon replay`'s accelerometer analysis, whether the recording is split into
chunks (the motion pass's mask applied to the accelerometers too) or not (the tasks run
here without Dask)."""
import numpy as np
import pyarrow.parquet as pq
import pytest
from helpers.doubles import ListSource

from fogmon.cli.batch import _accel_rows, _recording_row
from fogmon.fleet import tables, tasks
from fogmon.fleet.chunks import plan_chunks
from fogmon.pipeline import OVERALL_MAX_SAMPLES, PipelineConfig, run_pipeline
from fogmon.sources.options import SourceOptions

AXES = ("x", "y", "z")
FS = 100.0
N = 24_000
SRC, CFG = SourceOptions(), PipelineConfig(window_s=20.48, hop_s=20.48)


def source():
    rng = np.random.default_rng(9)
    rate = 60 * 0.05 * np.sqrt(FS) * rng.standard_normal((N, 3))
    rate[12_000:12_500, 1] += 2e4 * np.sin(np.linspace(0, np.pi, 500))     # y turns: its accelerometer follows
    acc = np.array([0.0, 0.0, 1.0]) + 100e-6 * np.sqrt(FS) * rng.standard_normal((N, 3))
    acc[3000:3020, 0] = np.nan
    t = np.arange(N) / FS
    sizes = [4096] * (N // 4096) + [N % 4096]
    return ListSource(t, rate, sizes, FS, aux={f"accel_{a}_g": acc[:, j] for j, a in enumerate(AXES)}, axes=AXES)


class Keep:
    def __init__(self):
        self.accel = {}

    def __getattr__(self, name):
        return lambda *a, **k: None

    def accel_frames(self, d, fit, t_end, accel):
        self.accel.setdefault(accel, []).append((d, fit, t_end))


@pytest.mark.parametrize("chunk_size", [8192, N])
def test_accelerometer_tables_equal_replay(monkeypatch, tmp_path, chunk_size):
    monkeypatch.setattr(tasks, "_open", lambda path, source_options: source())
    ref = Keep()
    summary = run_pipeline(source(), CFG, [ref])
    plan = tasks.check("three.csv", SRC, CFG)
    w = h = 2048
    chunks = plan_chunks(N, w, h, chunk_size, OVERALL_MAX_SAMPLES)
    rows, wins = [], []
    for a in AXES:
        masked = tasks.motion_pass(plan, SRC, CFG, a) if len(chunks) > 1 else None
        results = [tasks.run_chunk(plan, c, SRC, CFG, masked, a) for c in chunks]
        row, _ = _recording_row(plan, a, chunks, results, masked)
        assert row["error"] == ""
        for accel_row, accel_win in _accel_rows(plan, results):
            rows.append(accel_row)
            wins.append(accel_win)
    assert [r["accel"] for r in rows] == list(AXES)          # each axis's task: its own accelerometer
    tables.write_tables(str(tmp_path), [], [], wins, rows)
    got = pq.read_table(tmp_path / tables.ACCEL_WINDOWS).to_pandas()
    rec = pq.read_table(tmp_path / tables.ACCEL_RECORDINGS).to_pandas()
    for a in AXES:
        mine = got[got["accel"] == a]
        fits = ref.accel[a]
        vrw = np.concatenate([np.atleast_1d(f.VRW_mpsph.value) for _, f, _ in fits])
        t_end = np.concatenate([t for _, _, t in fits])
        np.testing.assert_allclose(mine["t_end_s"], t_end, rtol=0, atol=1e-9)
        np.testing.assert_allclose(mine["VRW_mpsph"], vrw, rtol=1e-9)
        adev = np.concatenate([d.adev_dph for d, _, _ in fits])
        np.testing.assert_allclose(mine[[tables.adev_column(tau, accel=True) for tau in fits[0][0].tau_s]], adev,
                                   rtol=1e-9)
        r = rec[rec["accel"] == a].iloc[0]
        whole = summary.accels[a]
        assert r["VRW_mpsph"] == pytest.approx(whole.overall_fit.VRW_mpsph.value, rel=1e-9)
        assert r["identifiable_Bias_ug"] == bool(whole.overall_fit.Bias_ug.identifiable)
        assert r["samples_invalid"] == whole.n_invalid == (20 if a == "x" else 0)
        assert r["windows"] == whole.n_windows
    assert summary.accels["y"].motion_samples > 0
    tables.write_tables(str(tmp_path), [], [])               # a later run without accelerometers
    assert not (tmp_path / tables.ACCEL_WINDOWS).exists() and not (tmp_path / tables.ACCEL_RECORDINGS).exists()
