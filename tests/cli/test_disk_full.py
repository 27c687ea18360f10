"""Issue 32.1: a write that fails (here a real one: a file-size limit, RLIMIT_FSIZE, set in
a subprocess; validation/faults_writers.py also fills a small tmpfs) is one line naming
the file and the free space, no traceback; every file written is readable (the archive
ends on a whole row and replays, no .tmp is left, no 0-byte report, a .rrd Rerun could
not complete is removed) and the exit code says so: 2 for a command, 1 for a monitor
(which still prints its summary)."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO

from fogmon.formats.replay_log import read_replay_log, write_replay_log

MODEL = str(REPO / "fogmon" / "data" / "example_model.toml")
#: the file-size limit (bytes): above every numba cache file (a cold cache is written
#: while the command runs), below the outputs made to fail
LIMIT = 2_000_000
EFBIG = "cannot write: File too large (a file-size limit: ulimit -f) ("


def limited(code: str, limit: int = LIMIT, at_write: bool = False, timeout: float = 600):
    """Run ``code`` (Python, may call ``main``) in a subprocess whose files may not grow
    beyond ``limit`` bytes (from its start, or with ``at_write`` from the first
    fogmon.outputs.written call on: the failure hits the outputs, not the imports)."""
    prelude = textwrap.dedent(f"""
        import contextlib, resource, sys
        sys.path.insert(0, {str(REPO / "tests")!r})
        def limit():
            resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
        if {at_write!r}:
            import fogmon.outputs as o
            _written = o.written
            @contextlib.contextmanager
            def written(*a, **k):
                limit()
                with _written(*a, **k) as tmp:
                    yield tmp
            o.written = written
        else:
            limit()
        from fogmon.cli import main
    """)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], capture_output=True, text=True,
                          env=env, timeout=timeout)


def _no_temp_files(folder: Path) -> None:
    left = [p.name for p in folder.rglob("*") if ".tmp" in p.name or p.name.startswith(".")]
    assert not left, left


@pytest.fixture(scope="module")
def long_log(tmp_path_factory) -> Path:
    """3000 s at 100 Hz with a temperature: a .rrd and a Parquet log of it exceed LIMIT."""
    path = tmp_path_factory.mktemp("log") / "long.csv"
    n = 300_000
    t = np.arange(n) / 100.0
    write_replay_log(path, t, np.random.default_rng(3).standard_normal(n) * 10, {"temp_c": 20 + t / 1000},
                     {"sample_rate_hz": 100})
    return path


@pytest.mark.timeout(900)
@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_archive_stops_on_a_whole_row_and_the_monitor_summary_says_why(tmp_path, fmt):
    """The archive as the monitor runs it (a pipeline with the console). CSV: the piece
    outgrows the limit, the run stops cleanly at the failed write with its summary, the
    piece ends on a whole row. Parquet: every row group is a small file, the piece's
    joined file outgrows the limit at the end: the parts are kept. Either way the
    archive replays, no .tmp is left and ``error`` names the file and the free space."""
    arch = tmp_path / "arch"
    p = limited(f"""
        import numpy as np
        from helpers.doubles import ListSource
        from fogmon.pipeline import PipelineConfig, run_pipeline
        from fogmon.sinks.archive import Archive
        from fogmon.sinks.console import ConsoleSink
        n = 400_000
        t = np.arange(n) / 1000.0
        src = ListSource(t, np.random.default_rng(0).standard_normal(n), [4096] * (n // 4096) + [n % 4096], 1000.0)
        archive = Archive({str(arch)!r}, src, samples_format={fmt!r}, row_group_s=2.0)
        s = run_pipeline(src, PipelineConfig(window_s=8.192), [ConsoleSink(), archive])
        print("ERROR", archive.error)
    """, limit=300_000)
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert "INCOMPLETE: writing stopped at a failed write" in p.stdout
    error = next(ln for ln in p.stdout.splitlines() if ln.startswith("ERROR "))
    assert "cannot write: File too large" in error and f" free in {arch})" in error
    _no_temp_files(arch)
    from fogmon.sources.open import open_replay_source
    src = open_replay_source(str(arch), None)                  # the archive replays: whole rows only
    n = sum(int(b.valid.sum()) for b in src.blocks())
    if fmt == "csv":
        assert "fogmon: stopped (the archive could not write: archive " in p.stdout   # the summary, and why
        rec = read_replay_log(arch / "samples-0001.csv")
        # whole rows up to the failed write: the rows of the write that failed which reached the file
        # are kept up to the last whole one, however many the flush thread had gathered into it
        assert 300_000 - 64 <= os.path.getsize(arch / "samples-0001.csv") <= 300_000 and len(rec) == n > 5_000
        np.testing.assert_allclose(rec.t_s, np.arange(n) / 1000.0)
    else:
        assert "fogmon: done: " in p.stdout and (arch / "samples-0001.parquet.parts").is_dir()
        assert n == 400_000                                    # every row group kept as a part


@pytest.mark.timeout(900)
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_sim_out_of_space_is_one_line_and_leaves_nothing(tmp_path, suffix):
    out = tmp_path / f"sim{suffix}"
    p = limited(f"sys.exit(main(['sim', '--model', {MODEL!r}, '--duration-s', '100000', '--seed', '1', "
                f"'--out', {str(out)!r}]))")
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    assert p.stderr.startswith(f"fogmon sim: error: --out {out}: {EFBIG}") and f" free in {tmp_path})" in p.stderr
    assert list(tmp_path.iterdir()) == []                      # no output, no temporary file


@pytest.mark.timeout(900)
def test_convert_out_of_space_leaves_no_tmp(tmp_path, long_log):
    out = tmp_path / "long.parquet"
    p = limited(f"sys.exit(main(['convert', {str(long_log)!r}, {str(out)!r}]))", limit=200_000)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    assert p.stderr.startswith(f"fogmon convert: error: OUT {out}: {EFBIG}")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.timeout(900)
def test_replay_rrd_out_of_space_is_removed_and_exits_2_after_the_summary(tmp_path, long_log):
    rrd = tmp_path / "long.rrd"
    p = limited(f"sys.exit(main(['replay', {str(long_log)!r}, '--rrd', {str(rrd)!r}, '--no-progress']))")
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert "Overall Allan deviation" in p.stdout                   # the summary is printed
    assert f"fogmon: warning: {rrd}: Rerun could not complete it" in p.stderr
    assert p.stderr.rstrip().splitlines()[-1].startswith(f"fogmon replay: error: --rrd {rrd}: cannot write: Rerun: ")
    assert list(tmp_path.iterdir()) == []                          # the broken .rrd is removed


@pytest.mark.timeout(900)
def test_explain_out_of_space_leaves_no_empty_report(tmp_path):
    rec, report = tmp_path / "rec.csv", tmp_path / "r.json"
    n = 4000
    write_replay_log(rec, np.arange(n) / 10.0, np.random.default_rng(2).standard_normal(n), None,
                     {"sample_rate_hz": 10})
    report.write_text("an earlier report\n")
    p = limited(f"sys.exit(main(['explain', {str(rec)!r}, '--report', {str(report)!r}, '--bootstrap', '8', "
                f"'--max-effects', '0', '--quiet']))", limit=10, at_write=True)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    assert p.stderr.startswith(f"fogmon explain: error: --report {report}: {EFBIG}")
    assert report.read_text() == "an earlier report\n"             # untouched: never half written
    assert sorted(x.name for x in tmp_path.iterdir()) == ["r.json", "rec.csv"]


@pytest.mark.timeout(600)
def test_export_out_of_space_is_one_line(tmp_path):
    curve, out = tmp_path / "curve.csv", tmp_path / "imu.yaml"
    curve.write_text("tau_s,adev_dph\n" + "".join(f"{2.0 ** k!r},{1.0 / 2 ** (k / 2)!r}\n" for k in range(8)))
    p = limited(f"sys.exit(main(['fit', {str(curve)!r}, '--export', 'kalibr', {str(out)!r}]))", limit=10,
                at_write=True)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert p.stderr.startswith(f"fogmon fit: error: --export kalibr {out}: {EFBIG}")
    assert sorted(x.name for x in tmp_path.iterdir()) == ["curve.csv"]
