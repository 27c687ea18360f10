import numpy as np
import pytest

from fogmon.errors import FogmonError
from fogmon.recording import read_replay_log, write_replay_log


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
    with pytest.raises(FogmonError, match="periods off the 10 Hz grid"):
        read_replay_log(p).to_block()
