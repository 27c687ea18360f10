"""Multi-axis replay logs (rate_<axis>_dph columns) read and written as CSV and Parquet,
and --axis picking axes when a replay source is opened."""
from __future__ import annotations

import numpy as np
import pytest

from fogmon.cli import build_parser, main
from fogmon.cli.source_options import source_options
from fogmon.errors import FogmonError
from fogmon.formats.parquet_log import ParquetLogWriter, read_parquet_log
from fogmon.formats.replay_log import ReplayLogReader, read_replay_log, write_replay_log
from fogmon.sources.open import open_replay_source

AXES = ("x", "y", "z")
FS = 10.0


def three_axis_log(path, n=400, gap=(100, 103)):
    """A 3-axis log at FS with samples gap[0]..gap[1]-1 missing, a shared temp_c and
    z's own temp_c_z; returns (t_s, rate_dph (n, 3), aux) of the rows written."""
    t = np.arange(n) / FS
    rate = np.random.default_rng(5).normal(0, 1, (n, 3)) + [10, 20, 30]
    keep = np.ones(n, bool)
    keep[gap[0]:gap[1]] = False
    aux = {"temp_c": 20 + t / 100, "temp_c_z": 40 - t / 100}
    t, rate, aux = t[keep], rate[keep], {k: v[keep] for k, v in aux.items()}
    write_replay_log(path, t, rate, aux, {"sample_rate_hz": FS, "sensor": "test IMU"}, axes=AXES)
    return t, rate, aux


def blocks_of(path, *opts):
    """The blocks `fogmon replay PATH OPTS` replays (its source, opened as the command does)."""
    argv = ["replay", str(path), *opts]
    args = build_parser(argv).parse_args(argv)
    src = open_replay_source(args.recording, source_options(args))
    return src, list(src.blocks())


def test_round_trip_three_axes_with_per_axis_aux_and_gap(tmp_path):
    p = tmp_path / "imu.csv"
    t, rate, aux = three_axis_log(p)
    assert p.read_text().splitlines()[3] == "time_s,rate_x_dph,rate_y_dph,rate_z_dph,temp_c,temp_c_z"
    rec = read_replay_log(p)
    assert rec.axes == AXES and rec.rate_dph.shape == (len(t), 3)
    np.testing.assert_allclose(rec.rate_dph, rate, rtol=1e-11)
    assert list(rec.aux) == ["temp_c", "temp_c_z"]
    z = rec.for_axis("z")
    np.testing.assert_allclose(z.aux["temp_c"], aux["temp_c_z"], rtol=1e-11)
    b = rec.to_block()
    assert b.axes == AXES and len(b) == 400 and not b.valid[100:103].any() and b.valid[103:].all()
    for chunk_bytes in (64, 1000):      # chunked reading gives the same rows, wherever the chunks fall
        parts = list(ReplayLogReader(p, chunk_bytes=chunk_bytes).chunks())
        np.testing.assert_array_equal(np.concatenate([r.rate_dph for r in parts]), rec.rate_dph)
        np.testing.assert_array_equal(np.concatenate([r.aux["temp_c_z"] for r in parts]), rec.aux["temp_c_z"])


def test_tolerant_reading_skips_bad_multi_axis_rows(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("# sample_rate_hz: 10\ntime_s,rate_x_dph,rate_y_dph\n0,1,2\n0.1,3,nan\n0.2,5,6\n0.3,7\n0.4,9,10\n")
    with pytest.raises(FogmonError, match=r"bad.csv: line 4, column rate_y_dph: nan is not a finite number"):
        read_replay_log(p)
    rec = read_replay_log(p, tolerate=True)
    assert rec.skipped_rows == 2
    np.testing.assert_array_equal(rec.rate_dph, [[1, 2], [5, 6], [9, 10]])
    parts = list(ReplayLogReader(p, tolerate=True, chunk_bytes=16).chunks())    # a few lines per chunk
    assert len(parts) == 3 and sum(r.skipped for r in parts) == 2
    np.testing.assert_array_equal(np.concatenate([r.rate_dph for r in parts]), rec.rate_dph)
    np.testing.assert_array_equal(rec.to_block().valid, [[True, True], [False, False], [True, True],
                                                         [False, False], [True, True]])


@pytest.mark.parametrize("header, message", [
    ("time_s,rate_dph,rate_x_dph", "line 2, column rate_x_dph: a header has rate_dph (one axis) or "
                                   "rate_<axis>_dph columns (several axes), not both"),
    ("time_s,temp_c", "line 2: missing required column 'rate_dph' (one axis) or rate_<axis>_dph columns"),
    ("time_s,rate_x_dph,rate_y-2_dph", "line 2, column rate_y-2_dph: axis name 'y-2' is not letters and digits"),
    ("time_s,rate_x_dph,rate__dph", "line 2, column rate__dph: axis name '' is not letters and digits"),
    ("t,rate_x_dph", "line 2: missing required column 'time_s'"),
])
def test_bad_multi_axis_headers_are_one_line_errors(tmp_path, capsys, header, message):
    p = tmp_path / "h.csv"
    p.write_text(f"# sample_rate_hz: 10\n{header}\n0,1,2\n")
    with pytest.raises(FogmonError) as e:
        read_replay_log(p)
    assert str(e.value).startswith(f"h.csv: {message}")
    assert main(["replay", str(p), "--no-progress", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err


def test_parquet_round_trip_and_bad_columns(tmp_path, capsys):
    p = tmp_path / "imu.csv"
    t, rate, aux = three_axis_log(p)
    out = tmp_path / "imu.parquet"
    assert main(["convert", str(p), str(out)]) == 0
    assert f"wrote {len(t)} samples" in capsys.readouterr().out
    rec = read_parquet_log(out)
    assert rec.axes == AXES and list(rec.aux) == ["temp_c", "temp_c_z"]
    np.testing.assert_allclose(rec.rate_dph, rate, rtol=1e-11)
    back = tmp_path / "back.csv"
    assert main(["convert", str(out), str(back)]) == 0
    np.testing.assert_allclose(read_replay_log(back).rate_dph, rate, rtol=1e-11)
    assert read_replay_log(back).axes == AXES
    both = tmp_path / "both.parquet"
    w = ParquetLogWriter(str(both), ["rate_dph"], {"sample_rate_hz": FS}, axes=("x",))
    w.write([0.0], [[1.0]], {"rate_dph": [2.0]})
    w.close()
    with pytest.raises(FogmonError, match=r"both.parquet, column rate_x_dph: a header has rate_dph .* not both"):
        read_parquet_log(both)


@pytest.mark.parametrize("suffix", ["csv", "parquet"])
def test_axis_option_picks_axes_of_csv_and_parquet(tmp_path, capsys, suffix):
    p = tmp_path / "imu.csv"
    t, rate, aux = three_axis_log(p)
    if suffix == "parquet":
        assert main(["convert", str(p), str(tmp_path / "imu.parquet")]) == 0
        p = tmp_path / "imu.parquet"
    src, blocks = blocks_of(p)
    assert src.axes == AXES and all(b.axes == AXES for b in blocks)
    assert sum(len(b) for b in blocks) == 400 and src.counters["samples_missing"] == 3
    src, blocks = blocks_of(p, "--axis", "z")
    assert src.axes == () and all(b.axes == () for b in blocks) and src.aux_names == ["temp_c"]
    b = blocks[0]
    np.testing.assert_allclose(b.rate_dph[b.valid], rate[:, 2], rtol=1e-11)
    np.testing.assert_allclose(b.aux["temp_c"][b.valid], aux["temp_c_z"], rtol=1e-11)   # z's own temperature
    src, blocks = blocks_of(p, "--axis", "z,x")
    assert src.axes == ("z", "x") and blocks[0].rate_dph.shape == (400, 2)
    np.testing.assert_allclose(blocks[0].rate_dph[blocks[0].valid[:, 0]], rate[:, [2, 0]], rtol=1e-11)
    assert sorted(blocks[0].aux) == ["temp_c", "temp_c_z"]
    src, blocks = blocks_of(p, "--axis", "y,x")
    assert sorted(blocks[0].aux) == src.aux_names == ["temp_c"]      # z's own channel left out
    assert main(["replay", str(p), "--axis", "w", "--no-progress", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"imu.{suffix}: no axis 'w' (axes: x, y, z)" in err


def test_axis_option_must_be_axis_names(tmp_path, capsys):
    with pytest.raises(SystemExit):
        build_parser(["replay", "x.csv", "--axis", "x,x"]).parse_args(["replay", "x.csv", "--axis", "x,x"])
    assert "an axis is named twice" in capsys.readouterr().err


def test_one_axis_log_ignores_axis_as_before(tmp_path):
    p = tmp_path / "one.csv"
    write_replay_log(p, np.arange(50) / FS, np.ones(50), None, {"sample_rate_hz": FS})
    src, blocks = blocks_of(p, "--axis", "x")
    assert src.axes == () and blocks[0].rate_dph.shape == (50,)


def test_archive_of_multi_axis_pieces_picks_axes_without_decoding_again(tmp_path):
    arch = tmp_path / "arch"
    arch.mkdir()
    rng = np.random.default_rng(1)
    for k, (a, b) in enumerate(((0, 100), (105, 200)), start=1):   # 5 samples missing at the seam
        t = np.arange(a, b) / FS
        write_replay_log(arch / f"samples-{k:04d}.csv", t, rng.normal(0, 1, (len(t), 3)), {"temp_c_y": t},
                         {"sample_rate_hz": FS}, axes=AXES)
    (arch / "raw-0001.bin").write_bytes(b"\x00" * 10)            # a capture beside it is not decoded for --axis
    src, blocks = blocks_of(arch)
    assert src.axes == AXES and sum(len(b) for b in blocks) == 200 and src.counters["samples_missing"] == 5
    assert all(b.rate_dph.shape == (len(b), 3) for b in blocks)
    src, blocks = blocks_of(arch, "--axis", "y")
    assert all(b.axes == () and sorted(b.aux) == ["temp_c"] for b in blocks)
    assert sum(int(b.valid.sum()) for b in blocks) == 195


@pytest.mark.parametrize("axis", ["x,w", "w"])
def test_imu_readers_take_x_y_z_all_one_or_several(axis):
    from fogmon.sources.files.stamped import imu_axes

    assert imu_axes(None, "run.bag") == ("x", "y", "z")
    assert imu_axes("z", "run.bag") == ("z",)
    assert imu_axes("y,x", "run.bag") == ("y", "x")
    with pytest.raises(FogmonError, match=rf"run.bag: axis {axis}: the gyro axes of an IMU are x, y and z"):
        imu_axes(axis, "run.bag")
    with pytest.raises(FogmonError, match="run.bag: axis x,x: an axis is named twice"):
        imu_axes("x,x", "run.bag")


def test_convert_keeps_rows_valid_on_every_axis_and_says_how_many_it_left_out(tmp_path, capsys):
    p = tmp_path / "imu.csv"
    p.write_text("# sample_rate_hz: 10\ntime_s,rate_x_dph,rate_y_dph,temp_c_y\n0,1,2,20\n0.1,3,1e30,21\n"
                 "0.2,5,6,22\n")                                    # 1e30 deg/h: implausible, invalid on y only
    out = tmp_path / "imu.parquet"
    assert main(["convert", str(p), str(out)]) == 0
    said = capsys.readouterr().out
    assert "wrote 2 samples" in said and "; 1 samples with only some axes valid left out" in said
    rec = read_parquet_log(out)
    np.testing.assert_array_equal(rec.rate_dph, [[1, 2], [5, 6]])
    assert main(["convert", str(p), str(tmp_path / "x.csv"), "--axis", "x"]) == 0
    x = read_replay_log(tmp_path / "x.csv")
    assert x.axes == () and list(x.aux) == [] and len(x) == 3
