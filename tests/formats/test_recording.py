import numpy as np
import pytest

from fogmon.errors import FogmonError
from fogmon.formats.replay_log import read_replay_log, write_replay_log


def _write(tmp_path, text, name="r.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_round_trip_with_metadata_and_aux(tmp_path):
    t = np.arange(100) / 10.0
    r = np.random.default_rng(1).normal(0, 3, 100)
    aux = {"temp_c": 25 + t / 100, "vib_g": np.full(100, 0.01)}
    p = tmp_path / "x.csv"
    write_replay_log(p, t, r, aux, {"sample_rate_hz": 10, "sensor": "test gyro"})
    rec = read_replay_log(p)
    assert rec.sample_rate_hz == 10
    assert rec.meta["sensor"] == "test gyro"
    np.testing.assert_allclose(rec.rate_dph, r, rtol=1e-11)
    np.testing.assert_allclose(rec.aux["temp_c"], aux["temp_c"], rtol=1e-11)
    assert list(rec.aux) == ["temp_c", "vib_g"]


@pytest.mark.parametrize("body, msg", [
    ("time_s,temp_c\n0,1\n", "missing required column 'rate_dph'"),
    ("time_s,rate_dph\n0,1\n0.1,abc\n", "line 5, column rate_dph: not a number: 'abc'"),
    ("time_s,rate_dph\n0,1\n0.1,nan\n", "line 5, column rate_dph: nan is not a finite number"),
    ("time_s,rate_dph\n0,1\n0.1,2\n0.05,3\n", "line 6, column time_s: time goes backwards"),
    ("time_s,rate_dph\n0,1\n0,2\n", "line 5, column time_s: time repeats"),
    ("time_s,rate_dph\n0,1\n0.1\n", "line 5: expected 2 cells"),
])
def test_bad_input_names_file_line_column(tmp_path, body, msg):
    p = _write(tmp_path, "# fogmon replay log v1\n# sample_rate_hz: 10\n" + body)
    with pytest.raises(FogmonError) as e:
        read_replay_log(p)
    assert str(e.value).startswith("r.csv: ")
    assert msg in str(e.value)
    assert "\n" not in str(e.value)


def test_tolerant_read_counts_skips(tmp_path):
    p = _write(tmp_path, "time_s,rate_dph\n0,1\n0.1,x\n0.2,nan\n0.3,4\n0.25,5\n0.4,6\n")
    rec = read_replay_log(p, tolerate=True)
    assert rec.skipped_rows == 3
    np.testing.assert_array_equal(rec.rate_dph, [1, 4, 6])


def test_time_gaps_become_invalid_placeholders(tmp_path):
    p = _write(tmp_path, "# sample_rate_hz: 10\ntime_s,rate_dph,temp_c\n0,1,20\n0.1,2,20\n0.4,5,21\n")
    b = read_replay_log(p).to_block()
    np.testing.assert_allclose(b.t_s, [0, 0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(b.valid, [True, True, False, False, True])
    assert np.isnan(b.rate_dph[2]) and np.isnan(b.aux["temp_c"][3])


def test_off_grid_sample_is_an_error(tmp_path):
    p = _write(tmp_path, "# sample_rate_hz: 10\ntime_s,rate_dph\n0,1\n0.1,2\n0.25,3\n")
    with pytest.raises(FogmonError, match="^r.csv: line 5, column time_s: sample at time_s=0.25 is 0.50 sample "
                                          "periods off the 10 Hz grid"):
        read_replay_log(p).to_block()


def _log_with(tmp_path, edit, n=3000):
    """A 100 Hz one-axis log of ``n`` rows (data from line 3) with ``edit(rows)`` applied."""
    rows = [f"{k / 100:.2f},1.5,20" for k in range(n)]
    edit(rows)
    return _write(tmp_path, "# sample_rate_hz: 100\ntime_s,rate_dph,temp_c\n" + "\n".join(rows) + "\n")


def test_whole_file_reader_names_the_line_as_the_streaming_one(tmp_path):
    """read_replay_log (sim --like, explain, updown, ...) and ReplayLogSource (replay,
    convert) name the same line of an off-grid sample and of a corrupt time-stamp jump,
    also after comment lines and rows skipped by a tolerant read, and of one axis."""
    from fogmon.sources.files.replay_log import ReplayLogSource

    def off_grid(rows):
        rows.insert(1000, "# a comment line")
        rows[2000] = "x,1,1"                           # skipped when tolerating
        rows[2500] = rows[2500].replace("24.99,", "24.995,")     # row 2499 after the comment

    def jump(rows):
        rows[1500:] = [f"{1e6 + k / 100:.2f},1.5,20" for k in range(1500, len(rows))]

    for edit, line, what in ((off_grid, 2503, "sample at time_s=24.995 is 0.50 sample periods off the 100 Hz "
                                               "grid (is sample_rate_hz right?)"),
                             (jump, 1503, "the time stamps span 1e+08 sample periods for 3000 samples (more than "
                                          "100 times as many missing as present; time_s jumps by 1e+06 s at "
                                          "this line): a corrupt time stamp or sample rate, not a gap")):
        p = _log_with(tmp_path, edit)
        want = f"r.csv: line {line}, column time_s: {what}"
        tolerate = edit is off_grid
        with pytest.raises(FogmonError) as streamed:
            ReplayLogSource(str(p), tolerate=tolerate, chunk_bytes=4096)
        rec = read_replay_log(p, tolerate=tolerate)
        for call in (rec.grid_index, rec.to_block, rec.for_axis("").grid_index):
            with pytest.raises(FogmonError) as whole:
                call()
            assert str(whole.value) == str(streamed.value) == want


def test_line_of_survives_pickling(tmp_path):
    import pickle
    p = _log_with(tmp_path, lambda rows: rows.insert(10, "# note"), n=50)
    rec = pickle.loads(pickle.dumps(read_replay_log(p)))
    assert rec.line_of(0) == 3 and rec.line_of(10) == 14


# -- the chunked reader: results and errors do not depend on where chunks are cut -------
from fogmon.formats.replay_log import ReplayLogReader  # noqa: E402


def _chunked(p, chunk_bytes, tolerate=False):
    parts = list(ReplayLogReader(p, tolerate=tolerate, chunk_bytes=chunk_bytes).chunks())
    return (np.concatenate([c.t_s for c in parts]), np.concatenate([c.rate_dph for c in parts]),
            np.concatenate([c.aux["temp_c"] for c in parts]), sum(c.skipped for c in parts), len(parts))


def test_chunked_read_equals_one_chunk_read(tmp_path):
    t = np.arange(3000) / 100.0
    p = tmp_path / "x.csv"
    write_replay_log(p, t, np.sin(t), {"temp_c": 20 + t / 10}, {"sample_rate_hz": 100})
    whole = read_replay_log(p)
    for chunk_bytes in (16, 97, 1000, 1 << 22):
        ts, rate, temp, skipped, n_parts = _chunked(p, chunk_bytes)
        assert (n_parts > 1) == (chunk_bytes < 1 << 22)
        np.testing.assert_array_equal(ts, whole.t_s)
        np.testing.assert_array_equal(rate, whole.rate_dph)
        np.testing.assert_array_equal(temp, whole.aux["temp_c"])


@pytest.mark.parametrize("bad, msg", [
    ("12.34,abc,20", "line 1237, column rate_dph: not a number: 'abc'"),
    ("12.34,inf,20", "line 1237, column rate_dph: inf is not a finite number"),
    ("12.34,1", "line 1237: expected 3 cells"),
    ("12.33,1,20", "line 1237, column time_s: time repeats"),
    ("12.30,1,20", "line 1237, column time_s: time goes backwards"),
])
def test_error_in_a_later_chunk_names_its_line(tmp_path, bad, msg):
    rows = [f"{k / 100:.2f},1.5,20" for k in range(2000)]
    rows[1234] = bad                        # data starts on line 3: row 1234 is line 1237
    p = _write(tmp_path, "# sample_rate_hz: 100\ntime_s,rate_dph,temp_c\n" + "\n".join(rows) + "\n")
    for chunk_bytes in (16, 50, 333, 4096, 1 << 22):
        with pytest.raises(FogmonError) as e:
            list(ReplayLogReader(p, chunk_bytes=chunk_bytes).chunks())
        assert str(e.value).startswith("r.csv: ") and msg in str(e.value), (chunk_bytes, str(e.value))


def test_tolerant_chunked_read_skips_the_same_rows(tmp_path):
    rows = [f"{k / 100:.2f},{k},20" for k in range(500)]
    rows[100], rows[250], rows[251] = "1.00,x,20", "2.49,1,20", "0.5,1,20"  # bad cell, repeat, backwards
    p = _write(tmp_path, "time_s,rate_dph,temp_c\n" + "\n".join(rows) + "\n")
    ref = read_replay_log(p, tolerate=True)
    assert ref.skipped_rows == 3
    for chunk_bytes in (16, 100, 1 << 22):
        ts, rate, _, skipped, _ = _chunked(p, chunk_bytes, tolerate=True)
        assert skipped == 3
        np.testing.assert_array_equal(rate, ref.rate_dph)


def test_bom_crlf_and_comment_lines_in_the_body(tmp_path):
    p = tmp_path / "bom.csv"
    p.write_bytes(b"\xef\xbb\xbf# fogmon replay log v1\r\n# sample_rate_hz: 10\r\ntime_s,rate_dph\r\n"
                  b"0,1\r\n# a note\r\n0.1,2\r\n\r\n0.2,3\r\n")
    for chunk_bytes in (16, 1 << 22):
        rec = read_replay_log(p) if chunk_bytes > 16 else None
        ts, rate = (rec.t_s, rec.rate_dph) if rec else (
            np.concatenate([c.t_s for c in ReplayLogReader(p, chunk_bytes=16).chunks()]),
            np.concatenate([c.rate_dph for c in ReplayLogReader(p, chunk_bytes=16).chunks()]))
        np.testing.assert_array_equal(rate, [1, 2, 3])
        np.testing.assert_array_equal(ts, [0, 0.1, 0.2])
    assert read_replay_log(p).sample_rate_hz == 10


def test_a_file_without_newlines_is_a_one_line_error(tmp_path):
    p = tmp_path / "blob.csv"
    p.write_bytes(b"time_s,rate_dph," + b"9" * (3 << 20))       # 3 MiB, no newline
    with pytest.raises(FogmonError) as e:
        ReplayLogReader(p)
    assert str(e.value) == "blob.csv: line 1 longer than 1048576 bytes (not a replay log?)"


def test_a_long_line_inside_a_chunk_is_named(tmp_path):
    rows = ["time_s,rate_dph"] + [f"{k / 10:.1f},1" for k in range(50)]
    rows[30] = "3.0," + "1" * 300
    p = _write(tmp_path, "\n".join(rows) + "\n")
    with pytest.raises(FogmonError, match=r"^r.csv: line 31 longer than 100 bytes"):
        list(ReplayLogReader(p, chunk_bytes=4096, max_line_bytes=100).chunks())


def test_long_cells_are_cut_in_messages_and_bad_utf8_is_named(tmp_path):
    p = _write(tmp_path, "time_s,rate_dph\n0,1\n0.1," + "x" * 5000 + "\n")
    with pytest.raises(FogmonError) as e:
        read_replay_log(p)
    assert "line 3, column rate_dph: not a number: 'xxxx" in str(e.value) and len(str(e.value)) < 200
    p = tmp_path / "latin1.csv"
    p.write_bytes(b"time_s,rate_dph\n0,1\n0.1,2\n0.2,\xb0\n")
    with pytest.raises(FogmonError, match=r"^latin1.csv: line 4: not UTF-8 text \(byte 5 of the line\)"):
        read_replay_log(p)


def test_header_only_file_is_a_one_line_error_without_warnings(tmp_path, recwarn):
    p = _write(tmp_path, "# fogmon replay log v1\ntime_s,rate_dph\n")
    with pytest.raises(FogmonError, match=r"^r.csv: no data rows$"):
        read_replay_log(p)
    assert not recwarn.list


def test_rate_without_metadata_from_the_first_samples(tmp_path):
    from fogmon.formats.recording import RATE_SAMPLES
    t = np.concatenate([np.arange(RATE_SAMPLES + 1) / 100.0,
                        RATE_SAMPLES / 100.0 + 1 + np.arange(RATE_SAMPLES * 2) / 50.0])
    p = tmp_path / "x.csv"
    write_replay_log(p, t, np.zeros(len(t)))
    assert read_replay_log(p).sample_rate_hz == pytest.approx(100.0)   # not the median of the whole file (50 Hz)
    assert ReplayLogReader(p, chunk_bytes=1000).sample_rate_hz == pytest.approx(100.0)
