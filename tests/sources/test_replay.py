"""Replay sources: replay-log CSV on its grid with gap events, raw serial captures
(--protocol or sidecar), bad files as one-line errors with file, line and column and
exit code 2 from `fogmon replay`."""
import json

import numpy as np
import pytest
from helpers.doubles import args_for
from helpers.fake_device import stream

from fogmon.cli import main
from fogmon.errors import FogmonError
from fogmon.formats.replay_log import write_replay_log
from fogmon.sources.files.replay_log import ReplayLogSource
from fogmon.sources.open import open_replay_source

HEAD = "# fogmon replay log v1\n# sample_rate_hz: 10\ntime_s,rate_dph,temp_c\n"


@pytest.mark.parametrize("body,where", [
    ("time_s,temp_c\n0,1\n", "line 1: missing required column 'rate_dph'"),
    (HEAD + "0.0,1.0,20\n0.1,abc,20\n", "line 5, column rate_dph: not a number: 'abc'"),
    (HEAD + "0.0,1.0,20\n0.2,1.0,20\n0.1,1.0,20\n", "line 6, column time_s: time goes backwards"),
    (HEAD + "0.0,1.0,20\n0.1,nan,20\n", "line 5, column rate_dph: nan is not a finite number"),
    (HEAD + "0.0,1.0,20\n0.1,1.0\n", "line 5: expected 3 cells"),
])
def test_bad_replay_logs_exit_2_with_file_line_column(tmp_path, capsys, body, where):
    p = tmp_path / "bad.csv"
    p.write_text(body)
    assert main(["replay", str(p), "--no-progress", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.csv" in err and where in err and "Traceback" not in err


def test_replay_log_grid_gaps_and_blocks(tmp_path):
    t = np.arange(20000) / 100.0
    keep = np.ones(len(t), bool)
    keep[[5, 6, 7, 9000]] = False
    p = tmp_path / "r.csv"
    write_replay_log(p, t[keep], np.arange(len(t))[keep] * 1.0, {"temp_c": np.ones(keep.sum())},
                     {"sample_rate_hz": 100})
    src = open_replay_source(str(p), args_for())
    assert isinstance(src, ReplayLogSource)
    bl = list(src.blocks())
    assert len(bl) == 3 and sum(len(b) for b in bl) == 20000
    valid = np.concatenate([b.valid for b in bl])
    np.testing.assert_array_equal(np.flatnonzero(~valid), [5, 6, 7, 9000])
    gaps = [e for b in bl for e in b.events]
    assert [(e.t_s, e.kind) for e in gaps] == [(0.05, "gap"), (90.0, "gap")] and "3 sample(s)" in gaps[0].message
    assert src.counters == {"samples": 19996, "samples_missing": 4, "seq_gaps": 2, "skipped_rows": 0,
                            "implausible_samples": 0}


def test_raw_capture_with_protocol_option_and_sidecar(tmp_path):
    data, intact = stream(300, {7: "drop", 100: "corrupt", 150: "garbage"})
    p = tmp_path / "cap.bin"
    p.write_bytes(data)
    with pytest.raises(FogmonError, match="not a replay log; for a raw serial capture give protocol "):
        open_replay_source(str(p), args_for())
    src = open_replay_source(str(p), args_for("--protocol", "kvh-a", "--kvh-rot", "rate", "--kvh-units", "deg",
                                              "--axis", "z", "--rate-hz", "200"))
    bl = list(src.blocks())
    v = np.concatenate([b.valid for b in bl])
    r = np.concatenate([b.rate_dph for b in bl])
    assert list(np.rint(r[v] / 3600).astype(int)) == intact and len(v) == 300
    assert src.sample_rate_hz == 200 and src.counters["crc_errors"] == 1 and src.counters["samples_missing"] == 2
    assert [e.kind for b in bl for e in b.events].count("crc_error") == 1
    assert src.n_samples == 300
    # a sidecar names the protocol; the command line still overrides it
    (tmp_path / "cap.bin.json").write_text(json.dumps({"format": "fogmon capture v1", "kind": "serial",
                                                       "protocol": "kvh-a", "kvh_rot": "rate", "kvh_units": "deg",
                                                       "sample_rate_hz": 200,
                                                       "breaks": [{"offset": 36 * 50, "missing_est": 130.0}]}))
    src = open_replay_source(str(p), args_for())
    assert sum(len(b) for b in src.blocks()) == 300 + 128     # the outage is put back where it was
    src = open_replay_source(str(p), args_for("--rate-hz", "400"))
    assert src.sample_rate_hz == 400


def test_bad_sidecar_is_one_line_error(tmp_path):
    (tmp_path / "cap.bin").write_bytes(b"\0" * 10)
    (tmp_path / "cap.bin.json").write_text("{not json")
    with pytest.raises(FogmonError, match="cap.bin.json: not a readable capture sidecar"):
        open_replay_source(str(tmp_path / "cap.bin"), args_for())


def test_dsp3000_capture_via_cli(tmp_path, capsys):
    p = tmp_path / "dsp.txt"
    p.write_bytes(b"".join(f"  {0.001 * (k % 7):.6f}   1\r\n".encode() for k in range(3000)))
    assert main(["replay", str(p), "--protocol", "dsp3000", "--no-progress"]) == 0   # default window from n_samples
    out = capsys.readouterr().out
    assert "3000" in out or "30.0" in out


def test_not_a_replay_log_without_protocol(tmp_path, capsys):
    p = tmp_path / "x.bin"
    p.write_bytes(b"\xfe\x81" * 10)
    assert main(["replay", str(p), "--quiet"]) == 2
    assert "--protocol" in capsys.readouterr().err


def test_pacer_waits_for_recording_time_over_speed():
    from fogmon.sources.pacing import Pacer
    now, slept = [0.0], []
    p = Pacer(2.0, clock=lambda: now[0], sleep=slept.append)
    p.wait(10.0)                 # sets the origin
    p.wait(11.0)                 # 1 s of recording at x2 -> 0.5 s of wall time
    now[0] = 0.2
    p.wait(12.0)
    assert slept == [0.5, pytest.approx(0.8)]
    Pacer(None, sleep=slept.append).wait(5.0)
    assert len(slept) == 2


# -- chunked replay: identical blocks whatever the chunk size, bounded gaps --------------
def _replay(path, **kw):
    src = ReplayLogSource(str(path), **kw)
    bl = list(src.blocks())
    return src, bl


def _flat(bl):
    return {"t": np.concatenate([b.t_s for b in bl]), "rate": np.concatenate([b.rate_dph for b in bl]),
            "valid": np.concatenate([b.valid for b in bl]), "temp": np.concatenate([b.aux["temp_c"] for b in bl]),
            "lens": [len(b) for b in bl], "events": [(e.t_s, e.kind, e.message) for b in bl for e in b.events]}


def test_chunk_seams_change_nothing(tmp_path):
    n = 40000
    keep = np.ones(n, bool)
    for a, b in ((0 + 1, 4), (777, 778), (8190, 8195), (9000, 30000), (39990, 39999)):   # one spans 3 blocks
        keep[a:b] = False
    t = np.arange(n)[keep] / 100.0
    p = tmp_path / "g.csv"
    write_replay_log(p, t, np.cos(t), {"temp_c": 20 + t / 1e3}, {"sample_rate_hz": 100})
    ref_src, ref = _replay(p)
    want = _flat(ref)
    assert want["lens"] == [8192] * 4 + [39999 - 4 * 8192 + 1]
    np.testing.assert_array_equal(np.flatnonzero(~want["valid"]), np.flatnonzero(~keep[:39999 + 1]))
    assert [m for _, _, m in want["events"]] == [
        "3 sample(s) missing at t=0.010000 s (time gap in the log)",
        "1 sample(s) missing at t=7.770000 s (time gap in the log)",
        "5 sample(s) missing at t=81.900000 s (time gap in the log)",
        "21000 sample(s) missing at t=90.000000 s (time gap in the log)",   # the whole gap, in the block it starts
        "9 sample(s) missing at t=399.900000 s (time gap in the log)"]
    assert ref_src.counters == {"samples": keep.sum(), "samples_missing": n - keep.sum(), "seq_gaps": 5,
                                "skipped_rows": 0, "implausible_samples": 0}
    assert ref_src.n_samples == n
    for chunk_bytes in (300, 4000, 65536):
        src, bl = _replay(p, chunk_bytes=chunk_bytes)
        got = _flat(bl)
        assert got["lens"] == want["lens"] and got["events"] == want["events"]
        for k in ("t", "rate", "valid", "temp"):
            np.testing.assert_array_equal(got[k], want[k])
        assert src.counters == ref_src.counters


def test_bad_row_deep_in_the_file_stops_before_any_block(tmp_path):
    t = np.arange(5000) / 100.0
    p = tmp_path / "late.csv"
    write_replay_log(p, t, np.zeros(5000), {"temp_c": np.ones(5000)}, {"sample_rate_hz": 100})
    text = p.read_text().splitlines()
    text[4000] = "39.975,0,1"                                     # off the 100 Hz grid
    p.write_text("\n".join(text) + "\n")
    with pytest.raises(FogmonError, match=r"^late.csv: line 4001, column time_s: sample at time_s=39.975 is "
                                          r"0.50 sample periods off the 100 Hz grid"):
        ReplayLogSource(str(p), chunk_bytes=512)


def test_implausible_rates_become_invalid_and_counted(tmp_path):
    t = np.arange(100) / 10.0
    r = np.ones(100)
    r[[3, 50]] = [1e30, -4e7]
    p = tmp_path / "x.csv"
    write_replay_log(p, t, r, {"temp_c": np.ones(100)}, {"sample_rate_hz": 10})
    src, bl = _replay(p, max_abs_dph=1e6)
    v = np.concatenate([b.valid for b in bl])
    np.testing.assert_array_equal(np.flatnonzero(~v), [3, 50])
    assert src.counters["implausible_samples"] == 2 and src.counters["samples"] == 100


def test_no_newline_file_via_cli_is_one_line_exit_2(tmp_path, capsys):
    p = tmp_path / "blob.csv"
    with open(p, "wb") as fh:                                     # 64 MiB without a newline
        fh.write(b"time_s,rate_dph\x00")
        for _ in range(64):
            fh.write(b"\x00" * (1 << 20))
    assert main(["replay", str(p), "--no-progress", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "blob.csv: line 1 longer than 1048576 bytes" in err and len(err) < 200


def test_archive_pieces_checked_when_opened(tmp_path):
    from fogmon.sources.files.replay_log import ReplayLogSet
    t = np.arange(300) / 10.0
    for k, sl in enumerate((slice(0, 100), slice(150, 300)), 1):
        write_replay_log(tmp_path / f"samples-000{k}.csv", t[sl], np.ones(len(t[sl])), {"temp_c": t[sl]},
                         {"sample_rate_hz": 10})
    s = ReplayLogSet([str(tmp_path / "samples-0001.csv"), str(tmp_path / "samples-0002.csv")])
    assert s.n_samples == 300
    bl = list(s.blocks())
    v = np.concatenate([b.valid for b in bl])
    np.testing.assert_array_equal(np.flatnonzero(~v), np.arange(100, 150))
    assert s.counters["samples_missing"] == 50 and s.counters["seq_gaps"] == 1 and s.counters["samples"] == 250
    with open(tmp_path / "samples-0002.csv", "a") as fh:
        fh.write("31,oops,1\n")
    with pytest.raises(FogmonError, match="samples-0002.csv: line .*, column rate_dph: not a number"):
        ReplayLogSet([str(tmp_path / "samples-0001.csv"), str(tmp_path / "samples-0002.csv")])
