"""`fogmon batch`: over a folder of simulated recordings in several formats (one split into
chunks, with platform motion the gate keeps out) it gives the numbers `fogmon replay`
gives for each recording (the same library: run_pipeline), to 1e-9; against a separately
started scheduler and two worker processes the output is identical."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from helpers.net import free_port

from fogmon.cli import main
from fogmon.fleet import tables
from fogmon.fleet.chunks import plan_chunks
from fogmon.fleet.tasks import _Collect, check
from fogmon.formats.replay_log import write_replay_log
from fogmon.pipeline import PipelineConfig, run_pipeline
from fogmon.sinks.base import COEFFICIENTS
from fogmon.sources.codecs.kvh import encode_frame
from fogmon.sources.open import open_replay_source
from fogmon.sources.options import SourceOptions


def _log(path, n, sample_rate_hz, seed, motion=False, gap=False):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / sample_rate_hz
    rate = 10.0 + 3.0 * rng.standard_normal(n) + np.cumsum(rng.standard_normal(n)) * 0.01
    if motion:                                   # a 30 s turn of 3000 deg/h, no rot_dps to explain it
        rate[n // 2:n // 2 + int(30 * sample_rate_hz)] += 3000.0
    keep = np.ones(n, bool)
    if gap:
        keep[n // 3:n // 3 + 25] = False
    write_replay_log(path, t[keep], rate[keep], {"temp_c": 25 + t[keep] / 1e4}, {"sample_rate_hz": sample_rate_hz})


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    _log(d / "a.csv", 30_000, 100.0, 1, gap=True)
    _log(d / "b.csv", 24_000, 100.0, 2)
    assert main(["convert", str(d / "b.csv"), str(d / "b.parquet")]) == 0
    (d / "b.csv").unlink()
    _log(d / "long.csv", 120_000, 100.0, 3, motion=True)      # split by --chunk-s 300 into several chunks
    rng = np.random.default_rng(4)                             # a KVH raw capture with its sidecar
    frames = [encode_frame("a", i % 128, (0.0, 0.0, 1e-7 * (1 + rng.standard_normal())), temp_c=30)
              for i in range(20_000)]
    del frames[7000:7003]
    (d / "kvh.bin").write_bytes(b"".join(frames))
    (d / "kvh.bin.json").write_text('{"format": "fogmon capture v1", "kind": "serial", "protocol": "kvh-a", '
                                    '"axis": "z"}\n')
    (d / "notes.txt").write_text("not a recording\n")
    return d


def _replay(path: str):
    """What `fogmon replay PATH` computes (its library: run_pipeline), collected."""
    plan = check(path, SourceOptions(), PipelineConfig())
    col = _Collect()
    run_pipeline(open_replay_source(path), PipelineConfig(), [col])
    return plan, col


@pytest.fixture(scope="module")
def local_run(fleet, tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    rc = main(["batch", str(fleet), "--out", str(out), "--workers", "2", "--chunk-s", "300", "--no-progress"])
    assert rc == 0
    return out


@pytest.mark.timeout(1200)   # a local Dask cluster on a 2-core machine shared with other jobs
def test_batch_equals_replay_per_recording(fleet, local_run, capsys):
    w = pq.read_table(local_run / tables.WINDOWS).to_pydict()
    r = {row["recording"]: row for row in pq.read_table(local_run / tables.RECORDINGS).to_pylist()}
    names = sorted(os.path.basename(k) for k in r)
    assert names == ["a.csv", "b.parquet", "kvh.bin", "long.csv"]
    assert r[str(fleet / "long.csv")]["chunks"] >= 3 and r[str(fleet / "kvh.bin")]["axis"] == "z"
    assert r[str(fleet / "long.csv")]["motion_samples_excluded"] > 3000    # the gate kept the turn out
    rec_col = np.array(w["recording"])
    for name, row in r.items():
        plan, col = _replay(name)
        s = col.summary
        assert row["error"] == "" and row["window_s"] == s.window_s and row["hop_s"] == s.hop_s
        assert (row["samples"], row["samples_invalid"]) == (s.n_samples, s.n_invalid)
        assert row["gaps"] == s.counters.get("seq_gaps", 0) and row["duration_s"] == pytest.approx(s.duration_s)
        assert row["motion_samples_excluded"] == s.motion_samples
        for c in COEFFICIENTS:
            co = getattr(s.overall_fit, c)
            np.testing.assert_allclose([row[c], row[f"{c}_lo"], row[f"{c}_hi"]], [co.value, co.lo, co.hi],
                                       rtol=1e-9, atol=0)
            assert row[f"identifiable_{c}"] == bool(co.identifiable)
        sel = rec_col == name
        ends = np.concatenate(col.gyro.ends)
        assert sel.sum() == len(ends) == row["windows"]
        np.testing.assert_allclose(
            np.array(w["t_end_s"])[sel], s.t_first_s + ends / s.sample_rate_hz, rtol=0, atol=1e-9
        )
        adev = np.concatenate(col.gyro.adev)
        for j, tau in enumerate(col.tau_s):
            np.testing.assert_allclose(np.array(w[tables.adev_column(tau)], float)[sel], adev[:, j], rtol=1e-9, atol=0)
        for c in tables.coefficient_columns():
            mine = np.array(w[c])[sel]
            ref = np.concatenate([f[c] for f in col.gyro.fits])
            if c.startswith("identifiable_"):
                np.testing.assert_array_equal(mine, ref)
            else:
                np.testing.assert_allclose(mine.astype(float), ref, rtol=1e-9, atol=0)


def test_chunks_tile_the_windows_and_samples():
    for n, w, h, size in ((120_000, 8192, 1024, 30_000), (1_000_003, 4096, 100, 50_000), (9000, 8192, 8192, 10)):
        ch = plan_chunks(n, w, h, size, 20_000)
        ks = np.concatenate([np.arange(c.k_first, c.k_stop) for c in ch])
        np.testing.assert_array_equal(ks, np.arange((n - w) // h + 1))
        assert [c.own_first for c in ch[1:]] == [c.own_stop for c in ch[:-1]] and ch[-1].own_stop == n
        for c in ch:
            assert c.feed_first <= c.k_first * h and c.feed_stop >= (c.k_stop - 1) * h + w
            assert (c.feed_first // h) % max(1, -(-max(h, w // 4) // h)) == 0      # on the refit grid
        assert ch[-1].feed_first <= n - min(n, 20_000)


@pytest.mark.timeout(600)
def test_unreadable_inputs_are_listed_and_the_readable_ones_analysed(fleet, tmp_path, capsys):
    """Issue 32.8: one unreadable input among good ones: the good ones are analysed and
    written, the bad one is named (stderr and recordings.parquet), exit 2; only bad
    inputs: nothing written."""
    bad = tmp_path / "bad"
    bad.mkdir()
    shutil.copy(fleet / "a.csv", bad / "a.csv")
    (bad / "z.csv").write_text("# fogmon replay log v1\ntime_s,rate_dph\n0,1\n0.01,x\n")
    rc = main(["batch", str(bad), "--out", str(tmp_path / "out"), "--workers", "1", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err
    assert "fogmon batch: error: z.csv: line 4, column rate_dph: not a number" in err
    assert err.rstrip().endswith("1 of 2 inputs could not be read (named above and in "
                                 f"{tmp_path / 'out' / 'recordings.parquet'}); the others are analysed")
    rows = {r["recording"]: r for r in pq.read_table(tmp_path / "out" / "recordings.parquet").to_pylist()}
    assert rows[str(bad / "a.csv")]["error"] == "" and rows[str(bad / "a.csv")]["windows"] > 0
    assert "not a number" in rows[str(bad / "z.csv")]["error"]
    (bad / "a.csv").unlink()
    assert main(["batch", str(bad), "--out", str(tmp_path / "o3"), "--workers", "1", "--no-progress"]) == 2
    assert capsys.readouterr().err.rstrip().endswith("no input could be read (1 named above): nothing analysed")
    assert not (tmp_path / "o3").exists()                    # nothing written
    assert main(["batch", str(tmp_path / "nothing*.csv"), "--out", str(tmp_path / "o2")]) == 2
    assert "no file matches" in capsys.readouterr().err


@pytest.mark.timeout(300)
def test_a_scheduler_without_workers_is_an_error_not_a_wait(fleet, tmp_path, capsys, monkeypatch):
    """Issue 32.8: batch gives up with an error when the cluster has no worker (here: none
    ever connected; the same wait ends a run whose workers all died)."""
    from distributed import LocalCluster

    import fogmon.cli.batch as batch

    monkeypatch.setattr(batch, "NO_WORKER_S", 1.0)
    with LocalCluster(n_workers=0, processes=False, dashboard_address=None) as cluster:
        addr = cluster.scheduler_address
        rc = main(["batch", str(fleet / "a.csv"), "--out", str(tmp_path / "out"), "--scheduler", addr,
                   "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and err == (f"fogmon batch: error: --scheduler {addr}: no Dask worker in 1 s (start one with "
                               f"`dask worker {addr}`)\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("address", "why"), [
    ("foo", "(PORT missing or not a number)"),
    ("http://x:99999", "(scheme one of tcp, tls, ws, wss, ucx)"),
    ("tcp://x:99999", "(a host and a port in 1..65535)"),
    ("tcp://:8786", "(a host and a port in 1..65535)"),
])
def test_a_bad_scheduler_address_is_a_usage_error_before_any_work(fleet, tmp_path, capsys, monkeypatch, address, why):
    """A --scheduler Dask cannot parse is one line naming the option and the value, exit
    2, before the inputs are even listed (no traceback from distributed's parser)."""
    import fogmon.fleet.inputs as inputs

    monkeypatch.setattr(inputs, "expand_inputs", lambda *a: pytest.fail("work started"))
    with pytest.raises(SystemExit) as e:
        main(["batch", str(fleet / "a.csv"), "--out", str(tmp_path / "out"), "--scheduler", address])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err == (f"fogmon batch: error: argument --scheduler: must be a Dask scheduler "
                                         f"address tcp://HOST:PORT {why}, got {address!r} (see fogmon batch --help)\n")
    assert not (tmp_path / "out").exists()


def test_outputs_inside_an_input_folder_are_refused_before_any_work(fleet, tmp_path, capsys, monkeypatch):
    """`batch b --out b` wrote its tables among the recordings of b, so the next `batch b`
    failed on them: an --out or --report in (or below) an input folder is one line naming
    the option, exit 2, before any cluster starts; nothing is written."""
    import fogmon.cli.batch as batch

    monkeypatch.setattr(batch, "_client", lambda *a: pytest.fail("work started"))
    b = tmp_path / "b"
    b.mkdir()
    shutil.copy(fleet / "a.csv", b / "a.csv")
    (tmp_path / "elsewhere").symlink_to(b)
    cases = [(["--out", str(b)], f"--out {b}: is the input folder {b}"),
             (["--out", str(b / "fleet")], f"--out {b / 'fleet'}: is inside the input folder {b}"),
             (["--out", str(tmp_path / "elsewhere" / "fleet")],
              f"--out {tmp_path / 'elsewhere' / 'fleet'}: is inside the input folder {b}"),
             (["--out", str(tmp_path / "out"), "--report", str(b / "fleet.html")],
              f"--report {b / 'fleet.html'}: is in the input folder {b}")]
    for inputs in ([str(b)], [str(tmp_path / "b*")]):          # a folder named, or matched by a glob
        for opts, message in cases:
            assert main(["batch", *inputs, *opts, "--no-progress"]) == 2
            assert capsys.readouterr().err == (f"fogmon batch: error: {message}, where a later batch over it would "
                                               f"read what is written as recordings; give a place outside it\n")
    assert sorted(p.name for p in b.iterdir()) == ["a.csv"] and not (tmp_path / "out").exists()


@pytest.mark.timeout(1200)
def test_separate_scheduler_and_two_workers_give_identical_output(fleet, local_run, tmp_path):
    from distributed import Client

    dask = str(Path(sys.executable).parent / "dask")
    port = free_port()
    addr = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(2):
            procs.append(subprocess.Popen([dask, "worker", addr, "--nthreads", "1", "--nworkers", "1",
                                           "--no-dashboard", "--host", "127.0.0.1"],
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(addr, timeout=120) as c:                     # synchronise on the cluster: both workers in
            c.wait_for_workers(2, timeout=240)
        out = tmp_path / "remote"
        assert main(["batch", str(fleet), "--out", str(out), "--scheduler", addr, "--chunk-s", "300",
                     "--no-progress"]) == 0
        for name in (tables.WINDOWS, tables.RECORDINGS):
            a, b = pq.read_table(out / name), pq.read_table(local_run / name)
            assert a.schema.equals(b.schema) and a.num_rows == b.num_rows, name
            for c in a.column_names:                             # identical, NaN where NaN
                x, y = a[c].to_pylist(), b[c].to_pylist()
                assert all(u == v or (u != u and v != v) for u, v in zip(x, y, strict=True)), (name, c)
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()


def _row(rec, n, n_hw, ident=True, score=None):
    row = {"recording": rec, "gyro": rec.split("/")[1], "gyro_named_by": "serial", "error": ""}
    for c, v, hw in (("N_dpsh", n, n_hw), ("B_dph", 0.1, 0.01)):
        row.update({c: v, f"{c}_lo": v - hw, f"{c}_hi": v + hw, f"identifiable_{c}": ident})
    if score is not None:
        row.update({"explain_score_before": score, "explain_score_after": 1.0, "explain_effects": "periodic"})
    return row


def test_fleet_report_names_the_changed_gyro_and_the_run_outside_its_model(tmp_path):
    import pyarrow as pa

    from fogmon.fleet.report import changes, write_report

    rows = [_row("rig/g1/run1.csv", 0.050, 0.001, score=1.0), _row("rig/g1/run2.csv", 0.0502, 0.001, score=1.1),
            _row("rig/g2/run1.csv", 0.050, 0.001, score=1.0), _row("rig/g2/run2.csv", 0.056, 0.001, score=2.4)]
    ch = {(c["gyro"], c["coefficient"][0]): c for c in changes(rows)}
    assert not ch[("g1", "N")]["changed"] and ch[("g2", "N")]["changed"]          # z = 0.14 vs 4.2
    assert ch[("g2", "N")]["z"] == pytest.approx(0.006 / np.hypot(0.001, 0.001))
    assert not ch[("g2", "B")]["changed"]
    rec = tmp_path / "recordings.parquet"
    pq.write_table(pa.Table.from_pylist(rows), rec)
    pq.write_table(pa.table({"recording": ["x"]}), tmp_path / "windows.parquet")
    files = write_report(str(tmp_path / "fleet.html"), str(rec), str(tmp_path / "windows.parquet"))
    assert [os.path.basename(f) for f in files] == ["fleet.html", "fleet-trends.png", "fleet.csv"]
    page = (tmp_path / "fleet.html").read_text()
    assert "Gyros whose N or B changed (1)" in page and "Runs outside their model (1)" in page
    assert "rig/g2/run2.csv" in page and (tmp_path / "fleet-trends.png").stat().st_size > 10_000
