"""Replay sources: replay-log CSV on its grid with gap events, raw serial captures
(--protocol or sidecar), bad files as one-line errors with file, line and column and
exit code 2 from `fogmon replay`."""
import argparse
import json

import numpy as np
import pytest

from fogmon.cli import main
from fogmon.errors import FogmonError
from fogmon.recording import write_replay_log
from fogmon.sources.open import add_source_arguments, open_replay_source
from fogmon.sources.replay import ReplayLogSource
from sources_fake_device import stream

HEAD = "# fogmon replay log v1\n# sample_rate_hz: 10\ntime_s,rate_dph,temp_c\n"


def args_for(*argv):
    p = argparse.ArgumentParser()
    add_source_arguments(p, mode="replay")
    return p.parse_args(list(argv))


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
    write_replay_log(p, t[keep], np.arange(len(t))[keep] * 1.0, {"temp_c": np.ones(keep.sum())}, {"sample_rate_hz": 100})
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
    with pytest.raises(FogmonError, match="not a replay log; for a raw serial capture give --protocol"):
        open_replay_source(str(p), args_for())
    src = open_replay_source(str(p), args_for("--protocol", "kvh-a", "--kvh-rot", "rate", "--kvh-units", "deg",
                                              "--rate-hz", "200"))
    bl = list(src.blocks())
    v = np.concatenate([b.valid for b in bl])
    r = np.concatenate([b.rate_dph for b in bl])
    assert list(np.rint(r[v] / 3600).astype(int)) == intact and len(v) == 300
    assert src.rate_hz == 200 and src.counters["crc_errors"] == 1 and src.counters["samples_missing"] == 2
    assert [e.kind for b in bl for e in b.events].count("crc_error") == 1
    assert src.n_samples == 300
    # a sidecar names the protocol; the command line still overrides it
    (tmp_path / "cap.bin.json").write_text(json.dumps({"format": "fogmon capture v1", "kind": "serial",
                                                       "protocol": "kvh-a", "kvh_rot": "rate", "kvh_units": "deg",
                                                       "rate_hz": 200, "breaks": [{"offset": 36 * 50, "missing_est": 130.0}]}))
    src = open_replay_source(str(p), args_for())
    assert sum(len(b) for b in src.blocks()) == 300 + 128     # the outage is put back where it was
    src = open_replay_source(str(p), args_for("--rate-hz", "400"))
    assert src.rate_hz == 400


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
