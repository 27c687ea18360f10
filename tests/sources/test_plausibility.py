"""The plausibility gate: every decoder and reader makes a rate no gyro can report an
invalid sample, counted (implausible_samples) and reported (implausible events, console
summary, Rerun event log); --max-rate-dph overrides the device range everywhere and
travels with a raw capture's sidecar. The issue's cases end to end through `fogmon
replay`: a DSP-3000 line `1e25 1`, CRC-valid KVH frames holding NaN, inf and 1e30, a
replay log holding 1e30 give exactly the result of a run in which that sample is
invalid."""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from helpers.rrd import read_scalars, read_texts

from fogmon.cli import main
from fogmon.errors import ERROR_COUNTERS, FogmonError
from fogmon.formats.capture import DECODER_FIELDS
from fogmon.formats.replay_log import write_replay_log
from fogmon.sources import plausibility as pl
from fogmon.sources.codecs.kvh import encode_frame
from fogmon.sources.codecs.protocols import codec_from_options, make_codec
from fogmon.sources.files.capture import open_raw_capture
from fogmon.sources.files.replay_log import ReplayLogSource
from fogmon.sources.grid import ErrorEvents, GridAssembler

RAD_TO_DPH = 180 / math.pi * 3600


# ----------------------------------------------------------------------------- gate()
def test_gate_replaces_and_counts_only_what_is_beyond():
    r = np.array([0.0, 3.0, -3.0, 3.0000001, -1e30, np.inf, np.nan])
    out, n = pl.gate(r, 3.0)
    np.testing.assert_array_equal(out, [0.0, 3.0, -3.0, np.nan, np.nan, np.nan, np.nan])
    assert n == 3                                 # a NaN is already an invalid sample: not counted
    ok = np.array([1.0, 2.0])
    assert pl.gate(ok, 3.0) == (ok, 0) and pl.gate(ok, 3.0)[0] is ok


def test_gate_with_device_flags_counts_garbage_in_valid_samples_only():
    r = np.array([np.nan, np.inf, 1e30, 1e30, 1.0])
    out, n = pl.gate(r, 10.0, valid=np.array([True, True, True, False, True]))
    np.testing.assert_array_equal(out, [np.nan, np.nan, np.nan, np.nan, 1.0])
    assert n == 3                                 # the flagged-invalid 1e30 is removed but not counted


@pytest.mark.parametrize("value", [0, -1.0, math.nan, math.inf, "x", "1e"])
def test_max_rate_dph_must_be_a_finite_positive_number(value):
    with pytest.raises(FogmonError, match="^max_rate_dph must be a finite number > 0 deg/h"):
        pl.max_rate_dph(value, 1.0)
    assert pl.max_rate_dph(None, 7.0) == 7.0 and pl.max_rate_dph(5, 7.0) == 5.0


def test_device_ranges():
    assert pl.KVH_DSP17XX_MAX_ABS_DPH == 490 * 3600 * 1.5 == 2_646_000
    assert pl.KVH_DSP3000_MAX_ABS_DPH == 375 * 3600 * 1.5 == 2_025_000
    assert pl.GENERIC_MAX_ABS_DPH == 36_000_000
    for name in (pl.COUNTER, pl.TEMP_COUNTER):
        assert ERROR_COUNTERS[name][0] == "implausible"


# ----------------------------------------------------------------------------- decoders
@pytest.mark.parametrize("fmt", ["a", "b", "c"])
def test_kvh_crc_valid_garbage_floats_are_invalid_and_counted(fmt):
    gz = [1e-6, math.nan, 2e-6, math.inf, -math.inf, 1e30, 3e-6, 1e30]
    status = [0x77] * 7 + [0x33]                   # the last one the device itself flagged invalid (z bit 2)
    data = b"".join(encode_frame(fmt, k, (0.0, 0.0, g), status=s, temp_c=30)
                    for k, (g, s) in enumerate(zip(gz, status, strict=True)))
    c = make_codec(f"kvh-{fmt}", kvh_rot="delta", kvh_units="rad", axis="z")
    events = ErrorEvents(c.counters)
    f = c.feed(data)
    assert c.counters["frames_ok"] == 8 and c.counters["crc_errors"] == 0
    assert c.counters["implausible_samples"] == 4      # NaN, inf, -inf, 1e30; not the flagged-invalid one
    good = np.isfinite(f.rate_dph)
    assert list(np.flatnonzero(good)) == [0, 2, 6]
    np.testing.assert_allclose(f.rate_dph[good], np.float32([1e-6, 2e-6, 3e-6]) * RAD_TO_DPH * 1000, rtol=1e-6)
    g = GridAssembler(c.sample_rate_hz, c.seq_modulus, c.aux_names)
    b = g.push(f)
    assert list(np.flatnonzero(b.valid)) == [0, 2, 6] and g.counters["invalid_samples"] == 5
    (e,) = events.poll(1.0)
    assert e.kind == "implausible" and e.message.startswith("4 sample(s) with an implausible rate")
    assert e.message.endswith("(4 so far)")


def test_kvh_gate_edge_and_override():
    """At 1 kHz delta-rad, the gate +-2,646,000 deg/h is 0.012828 rad per sample."""
    edge = pl.KVH_DSP17XX_MAX_ABS_DPH / RAD_TO_DPH / 1000
    data = b"".join(encode_frame("a", k, (0, 0, v)) for k, v in enumerate([0.99 * edge, 1.01 * edge]))
    c = make_codec("kvh-a", axis="z")
    assert list(np.isfinite(c.feed(data).rate_dph)) == [True, False] and c.counters["implausible_samples"] == 1
    c = make_codec("kvh-a", axis="z", max_rate_dph=1e7)
    assert list(np.isfinite(c.feed(data).rate_dph)) == [True, True] and c.counters["implausible_samples"] == 0
    c = make_codec("kvh-a", axis="z", max_rate_dph=1e5)
    assert list(np.isfinite(c.feed(data).rate_dph)) == [False, False] and c.counters["implausible_samples"] == 2


@pytest.mark.parametrize("fmt", ["a", "b"])
def test_kvh_implausible_temperature_is_nan_and_counted(fmt):
    temps = [25, 200, -61, -60, 125, 126, 30]
    data = b"".join(encode_frame(fmt, k, (0, 0, 1e-6), temp_c=t) for k, t in enumerate(temps))
    c = make_codec(f"kvh-{fmt}")
    f = c.feed(data)
    np.testing.assert_array_equal(f.aux["temp_c"], [25, np.nan, np.nan, -60, 125, np.nan, 30])
    assert c.counters["implausible_temp_c"] == 3 and c.counters["implausible_samples"] == 0
    assert np.isfinite(f.rate_dph).all()           # the rate of such a frame stays a sample


def test_kvh_format_c_temperature_reading_held_until_the_next_one():
    temps = {0: 25.0, 4: math.nan, 8: 1e30, 12: 40.0}   # format C sends the temperature when seq % 4 == 0
    data = b"".join(encode_frame("c", k, (0, 0, 1e-6), temp_c=temps.get(k, 0.0)) for k in range(14))
    c = make_codec("kvh-c")
    t = c.feed(data).aux["temp_c"]
    np.testing.assert_array_equal(t, [25.0] * 4 + [np.nan] * 8 + [40.0] * 2)
    assert c.counters["implausible_temp_c"] == 2


def test_dsp3000_1e25_line():
    c = make_codec("dsp3000")
    f = c.feed(b"  0.010000   1\r\n1e25 1\r\n1e25 0\r\n  562.5 1\r\n  562.6 1\r\n-0.02 1\r\n")
    np.testing.assert_array_equal(f.rate_dph, [36.0, np.nan, np.nan, 2_025_000.0, np.nan, -72.0])
    assert list(f.valid) == [True, True, False, True, True, True]
    assert c.counters == {"frames_ok": 6, "bad_lines": 0, "bytes_skipped": 0, "implausible_samples": 2}


def test_lines_gate_default_and_override():
    c = make_codec("lines", columns="rate_dps,valid")
    f = c.feed(b"9999,1\n10001,1\n1e300,1\n-1e308,1\n10001,0\n")
    assert list(np.isfinite(f.rate_dph)) == [True, False, False, False, False]
    assert c.counters["implausible_samples"] == 3 and c.counters["bad_lines"] == 0
    c = make_codec("lines", columns="rate_dph", max_rate_dph=100)
    f = c.feed(b"99\n101\n-100\n")
    assert list(np.isfinite(f.rate_dph)) == [True, False, True] and c.counters["implausible_samples"] == 1


# ----------------------------------------------------------------------------- option plumbing
def test_codec_options_carry_the_gate_and_rebuild_it():
    assert "max_rate_dph" in DECODER_FIELDS
    for protocol, default in (("kvh-b", pl.KVH_DSP17XX_MAX_ABS_DPH), ("dsp3000", pl.KVH_DSP3000_MAX_ABS_DPH),
                              ("lines", pl.GENERIC_MAX_ABS_DPH)):
        assert make_codec(protocol).options()["max_rate_dph"] == default
        o = make_codec(protocol, max_rate_dph=123.0).options()
        assert o["max_rate_dph"] == 123.0 and codec_from_options(o).max_rate_dph == 123.0


def kvh_capture(path, gz, status=None, sidecar=None):
    """A raw KVH format A capture (delta rad, 1 kHz) of frames with z = gz[k]."""
    status = status or [0x77] * len(gz)
    path.write_bytes(b"".join(encode_frame("a", k % 128, (0.0, 0.0, g), status=s, temp_c=30)
                              for k, (g, s) in enumerate(zip(gz, status, strict=True))))
    if sidecar is not None:
        path.with_name(path.name + ".json").write_text(json.dumps({"format": "fogmon capture v1", "kind": "serial",
                                                                  "protocol": "kvh-a", **sidecar}))
    return str(path)


def test_raw_capture_replays_with_its_sidecars_gate_and_the_command_line_wins(tmp_path):
    gz = [1e-6, 0.02, 1e-6]                        # 0.02 rad per sample at 1 kHz = 4.1e6 deg/h
    p = kvh_capture(tmp_path / "raw.bin", gz, sidecar={"max_rate_dph": 5e6})
    src = open_raw_capture(p)
    assert all(b.valid.all() for b in src.blocks()) and src.counters["implausible_samples"] == 0
    src = open_raw_capture(p, {"max_rate_dph": 1e6})
    assert sum(int((~b.valid).sum()) for b in src.blocks()) == 1 and src.counters["implausible_samples"] == 1
    p2 = kvh_capture(tmp_path / "raw2.bin", gz, sidecar={})
    src = open_raw_capture(p2)                      # no value recorded: the device range
    assert [int((~b.valid).sum()) for b in src.blocks()] == [1] and src.counters["implausible_samples"] == 1


def test_a_bad_max_rate_dph_in_a_sidecar_is_one_line_naming_it(tmp_path, capsys):
    p = kvh_capture(tmp_path / "raw.bin", [1e-6] * 4, sidecar={"max_rate_dph": -1})
    assert main(["replay", p, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"fogmon replay: error: {p}.json: field max_rate_dph: expected a number > 0, got -1"


@pytest.mark.parametrize("value", ["0", "-3", "nan", "inf", "abc"])
def test_max_rate_dph_option_is_validated(tmp_path, capsys, value):
    with pytest.raises(SystemExit) as e:
        main(["replay", str(tmp_path / "x.csv"), "--max-rate-dph", value])
    assert e.value.code == 2
    assert "argument --max-rate-dph: must be a finite number > 0" in capsys.readouterr().err


def test_monitor_and_replay_offer_the_option(capsys):
    for cmd in ("monitor", "replay"):
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        out = " ".join(capsys.readouterr().out.split())
        assert "--max-rate-dph DEG/H" in out and "kvh-a/b/c 2,646,000 (490 deg/s)" in out
        assert "dsp3000 2,025,000 (375 deg/s)" in out and "36,000,000 (10,000 deg/s)" in out


# ----------------------------------------------------------------------------- replay logs
def noisy(n=6000, sample_rate_hz=50.0, seed=11):
    rng = np.random.default_rng(seed)
    return np.arange(n) / sample_rate_hz, 2.0 + 40.0 * rng.standard_normal(n), sample_rate_hz


def test_replay_log_source_gates_each_block(tmp_path):
    t, r, sample_rate_hz = noisy()
    r = r.copy()
    r[[10, 5000]] = [1e30, -4e7]
    write_replay_log(tmp_path / "x.csv", t, r, {}, {"sample_rate_hz": sample_rate_hz})
    src = ReplayLogSource(str(tmp_path / "x.csv"))
    bl = list(src.blocks())
    valid = np.concatenate([b.valid for b in bl])
    rate = np.concatenate([b.rate_dph for b in bl])
    assert list(np.flatnonzero(~valid)) == [10, 5000] and np.isnan(rate[[10, 5000]]).all()
    assert src.counters["implausible_samples"] == 2
    ev = [e for b in bl for e in b.events]
    assert [e.kind for e in ev] == ["implausible"] and ev[0].message.endswith("(2 so far)")
    assert ev[0].t_s == t[10]                       # at the first implausible sample
    src = ReplayLogSource(str(tmp_path / "x.csv"), max_abs_dph=1e40)
    assert all(b.valid.all() for b in src.blocks()) and src.counters["implausible_samples"] == 0


# ----------------------------------------------------------------------------- end to end
def replay(capsys, path, tmp_path, name, *extra):
    out = tmp_path / f"{name}.rrd"
    rc = main(["replay", str(path), "--rrd", str(out), "--window-s", "20.48", "--hop-s", "5.12", "--no-progress",
               *extra])
    text = capsys.readouterr()
    return rc, text.out, text.err, out


def adev_part(out: str) -> str:
    """The summary from the overall ADEV table to the end of the fit (what the data decide)."""
    return out[out.index("Overall Allan deviation"):out.index("Counters:")]


def counter(out: str, name: str) -> int:
    return int(re.search(rf"^\s+{name}\s+(\d+)$", out, re.M).group(1))


def check_same_run(capsys, tmp_path, bad, ref, n_bad, *extra):
    """Replaying ``bad`` exits 0, names ``n_bad`` implausible samples, and gives the ADEV,
    fit and DADEV of ``ref`` (the same recording with those samples invalid), all finite."""
    rc, out, err, rrd = replay(capsys, bad, tmp_path, "bad", *extra)
    assert rc == 0, err
    assert counter(out, "implausible_samples") == n_bad and counter(out, "events.implausible") >= 1
    assert "implausible: " in err and "sample(s) with an implausible rate" in err
    rc, ref_out, _, ref_rrd = replay(capsys, ref, tmp_path, "ref", *extra)
    assert rc == 0 and counter(ref_out, "implausible_samples") == 0
    assert adev_part(out) == adev_part(ref_out)
    assert "nan" not in adev_part(out).split("IEEE-952")[0]
    _, got = read_scalars(str(rrd), "/dadev/log10_adev_dph")
    _, want = read_scalars(str(ref_rrd), "/dadev/log10_adev_dph")
    assert got.size and np.isfinite(got).all()
    np.testing.assert_array_equal(got, want)
    assert any("implausible" in x for x in read_texts(str(rrd), "/events"))
    return out


def test_replay_log_holding_1e30(tmp_path, capsys):
    t, r, sample_rate_hz = noisy()
    write_replay_log(
        tmp_path / "ref.csv", np.delete(t, 3000), np.delete(r, 3000), {}, {"sample_rate_hz": sample_rate_hz}
    )
    r = r.copy()
    r[3000] = 1e30
    write_replay_log(tmp_path / "bad.csv", t, r, {}, {"sample_rate_hz": sample_rate_hz})
    out = check_same_run(capsys, tmp_path, tmp_path / "bad.csv", tmp_path / "ref.csv", 1)
    assert "(1 invalid/lost)" in out


def test_replay_log_and_max_rate_dph(tmp_path, capsys):
    t, r, sample_rate_hz = noisy()
    r = r.copy()
    r[100] = 5000.0                                # plausible for the generic gate, not for a 1000 deg/h one
    write_replay_log(tmp_path / "x.csv", t, r, {}, {"sample_rate_hz": sample_rate_hz})
    rc, out, _, _ = replay(capsys, tmp_path / "x.csv", tmp_path, "a")
    assert rc == 0 and counter(out, "implausible_samples") == 0
    rc, out, _, _ = replay(capsys, tmp_path / "x.csv", tmp_path, "b", "--max-rate-dph", "1000")
    assert rc == 0 and counter(out, "implausible_samples") == 1


def test_dsp3000_capture_with_a_1e25_line(tmp_path, capsys):
    _, r, sample_rate_hz = noisy()
    lines = [f"  {v / 3600:.6f}   1\r\n" for v in r]
    ref = lines.copy()
    lines[2500] = "1e25 1\r\n"
    ref[2500] = "  0.000000   0\r\n"                # the same sample, flagged invalid by the device
    (tmp_path / "bad.txt").write_text("".join(lines))
    (tmp_path / "ref.txt").write_text("".join(ref))
    check_same_run(capsys, tmp_path, tmp_path / "bad.txt", tmp_path / "ref.txt", 1,
                   "--protocol", "dsp3000", "--rate-hz", str(sample_rate_hz))


def test_kvh_capture_with_garbage_floats(tmp_path, capsys):
    _, r, sample_rate_hz = noisy(n=24000, sample_rate_hz=200.0)
    gz = list(r / RAD_TO_DPH / sample_rate_hz)
    status = [0x77] * len(gz)
    bad = gz.copy()
    for k, v in ((5000, math.nan), (9000, math.inf), (15000, 1e30)):
        bad[k] = v
        status[k] = 0x33                            # in the reference the device flags the sample invalid
    check_same_run(capsys, tmp_path, kvh_capture(tmp_path / "bad.bin", bad),
                   kvh_capture(tmp_path / "ref.bin", gz, status),
                   3, "--protocol", "kvh-a", "--axis", "z", "--rate-hz", str(sample_rate_hz))


def test_monitor_archive_sidecar_records_the_gate_and_its_replay_uses_it(tmp_path, capsys):
    """What `fogmon monitor --max-rate-dph` stores: the archive's raw-capture sidecar holds
    the gate in force, so replaying the capture gates the same samples."""
    import argparse

    from fogmon.cli.source_options import add_source_arguments, source_options
    from fogmon.sinks.archive import Archive
    from fogmon.sources.open import open_live_source

    parser = argparse.ArgumentParser()
    add_source_arguments(parser, mode="live")
    src = open_live_source(source_options(parser.parse_args(["--serial", "loop://", "--protocol", "dsp3000",
                                                             "--max-rate-dph", "180"])))
    data = b"0.01 1\r\n0.06 1\r\n-0.049 1\r\n" * 4    # 36, 216, -176.4 deg/h
    with Archive(str(tmp_path / "arch"), src, background_flush=False) as a:
        a.raw(data)
        src.codec.feed(data)
        cap = a.capture_path
    assert json.loads((tmp_path / "arch" / "raw-0001.bin.json").read_text())["max_rate_dph"] == 180.0
    assert main(["replay", cap, "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert counter(out, "implausible_samples") == 4 and "12 samples at 100 Hz" in out and "(4 invalid/lost)" in out


def test_max_rate_dph_on_an_archive_folder_gates_its_replay_logs_without_decoding_again(tmp_path):
    from helpers.doubles import args_for

    from fogmon.sources.files.replay_log import ReplayLogSet
    from fogmon.sources.open import open_replay_source

    t, r, sample_rate_hz = noisy(n=200)
    for k, sl in ((1, slice(0, 100)), (2, slice(100, 200))):
        write_replay_log(
            tmp_path / f"samples-000{k}.csv", t[sl], r[sl], {}, {"sample_rate_hz": sample_rate_hz, "piece": k}
        )
    kvh_capture(tmp_path / "raw-0001.bin", [1e-6] * 10, sidecar={})
    src = open_replay_source(str(tmp_path), args_for("--max-rate-dph", "50"))
    assert isinstance(src, ReplayLogSet)
    valid = np.concatenate([b.valid for b in src.blocks()])
    assert list(np.flatnonzero(~valid)) == list(np.flatnonzero(np.abs(r) > 50))
    assert src.counters["implausible_samples"] == int(np.count_nonzero(np.abs(r) > 50)) > 0


def test_whole_file_commands_gate_a_replay_log_too(tmp_path, capsys):
    """read_recording (explain, inorbit, updown, sim --like, thermal) gates a replay log as
    the replay does: implausible samples become time gaps, counted in a warning; a record
    with nothing plausible is one line, exit 2."""
    from fogmon.sources.open import read_recording
    from fogmon.sources.options import SourceOptions

    t, r, sample_rate_hz = noisy()
    r = r.copy()
    r[100:105] = 1e9
    write_replay_log(tmp_path / "x.csv", t, r, {}, {"sample_rate_hz": sample_rate_hz})
    with pytest.warns(Warning, match=r"x.csv: 5 sample\(s\) with a rate beyond the plausibility gate"):
        rec = read_recording(tmp_path / "x.csv")
    assert len(rec) == len(t) - 5 and np.all(np.abs(rec.rate_dph) < 1e9)
    assert rec.line_of(100) == 109    # the sample after the 5 gated still names its own line (3 header lines)
    with pytest.warns(Warning, match=r"x.csv: 6 sample\(s\)"):   # the gate the user sets
        r[200] = 5000.0
        write_replay_log(tmp_path / "x.csv", t, r, {}, {"sample_rate_hz": sample_rate_hz})
        read_recording(tmp_path / "x.csv", SourceOptions(max_rate_dph=1000.0))
    write_replay_log(tmp_path / "all.csv", t, np.full(len(t), 1e12), {}, {"sample_rate_hz": sample_rate_hz})
    assert main(["inorbit", str(tmp_path / "all.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "all.csv: no valid samples: every rate is beyond the plausibility gate" in err
