"""ASCII codecs: KVH DSP-3000 lines and column-mapped generic lines (values, units,
bad-line accounting, bounded buffers) and hypothesis property tests."""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from fogmon.errors import FogmonError
from fogmon.sources.codecs.dsp3000 import Dsp3000Codec
from fogmon.sources.codecs.lines import LinesCodec, parse_columns
from fogmon.sources.codecs.protocols import make_codec
from fogmon.sources.plausibility import KVH_DSP3000_MAX_ABS_DPH


def test_dsp3000_lines():
    c = Dsp3000Codec()
    data = b"       0.015733   1\r\n      -0.002000   0\r\nBOOT DSP-3000\r\n\r\n   1e-3 1\r\n   0.5"
    f = c.feed(data)
    np.testing.assert_allclose(f.rate_dph, [0.015733 * 3600, -0.002 * 3600, 3.6])
    assert list(f.valid) == [True, False, True] and list(f.seq) == [-1, -1, -1]
    assert c.counters == {"frames_ok": 3, "bad_lines": 1, "bytes_skipped": len(b"BOOT DSP-3000\r\n\r\n"),
                          "implausible_samples": 0}
    assert c.pending == len(b"   0.5")
    f = c.feed(b"   1\r\n")
    assert f.rate_dph[0] == pytest.approx(1800.0)


def test_dsp3000_delta_mode_and_long_garbage():
    c = Dsp3000Codec(rot="delta", sample_rate_hz=100)
    f = c.feed(b"x" * 5000 + b"\n  0.001 1\n")
    assert f.rate_dph[0] == pytest.approx(0.001 * 3600 * 100)
    assert c.counters["bad_lines"] == 1 and c.counters["bytes_skipped"] == 5001 and c.pending == 0


def test_lines_column_map_units_and_counter():
    c = LinesCodec("seq:16,rate_rps,temp_c,-,valid", sample_rate_hz=50)
    f = c.feed(b"# header\n15,0.001,25.5,abc,1\n0;0.002;25.6;x;0\n3\t-0.001\t25.7\t0\t1\nbad,1,2\n")
    np.testing.assert_allclose(f.rate_dph, np.array([0.001, 0.002, -0.001]) * 180 / math.pi * 3600)
    assert list(f.seq) == [15, 0, 3] and list(f.valid) == [True, False, True]
    np.testing.assert_array_equal(f.aux["temp_c"], [25.5, 25.6, 25.7])
    assert c.aux_names == ("temp_c",) and c.seq_modulus == 16
    assert c.counters["frames_ok"] == 3 and c.counters["bad_lines"] == 2


@pytest.mark.parametrize("spec,scale", [("rate_dph", 1.0), ("rate_dps", 3600.0), ("delta_deg", 3600.0 * 20),
                                        ("delta_arcsec", 20.0), ("delta_rad", 180 / math.pi * 3600 * 20)])
def test_lines_rate_units(spec, scale):
    f = LinesCodec(spec, sample_rate_hz=20).feed(b"2.5\n")
    assert f.rate_dph[0] == pytest.approx(2.5 * scale, rel=1e-12)


@pytest.mark.parametrize("spec,what", [("temp_c", "exactly one rate"), ("rate_dph,rate_dps", "exactly one rate"),
                                       ("rate_dph,seq:1", "seq:N"), ("rate_dph,time_s", "time_s"),
                                       ("rate_dph,temp_c,temp_c", "more than once"), ("rate_dph,2x", "'2x'")])
def test_bad_column_maps_are_one_line_errors(spec, what):
    with pytest.raises(FogmonError, match=what.replace("(", r"\(")) as e:
        parse_columns(spec)
    assert "\n" not in str(e.value)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600), st.integers(1, 50), st.sampled_from(["dsp3000", "lines"]))
def test_property_ascii_codecs_never_raise_and_account(data, chunk, protocol):
    c = make_codec(protocol, columns="seq:256,rate_dps,temp_c")
    out = [c.feed(data[i:i + chunk]) for i in range(0, len(data), chunk)]
    n = sum(len(o) for o in out)
    assert n == c.counters["frames_ok"]
    assert all(np.isfinite(o.rate_dph).all() for o in out)
    assert c.counters["bytes_skipped"] + c.pending <= len(data)
    assert c.pending <= 512


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.floats(-1e4, 1e4, allow_nan=False), st.booleans()), max_size=30), st.integers(1, 40))
def test_property_dsp3000_roundtrip_any_chunking(samples, chunk):
    data = b"".join(f"  {v:.6f}   {int(ok)}\r\n".encode() for v, ok in samples)
    c = Dsp3000Codec()
    out = [c.feed(data[i:i + chunk]) for i in range(0, len(data), chunk)]
    rate = np.concatenate([o.rate_dph for o in out]) if out else np.zeros(0)
    dph = [float(f"{v:.6f}") * 3600 for v, _ in samples]
    plausible = [abs(r) <= KVH_DSP3000_MAX_ABS_DPH for r in dph]     # beyond the gate: NaN, counted if flagged valid
    np.testing.assert_allclose(rate, [r if p else np.nan for r, p in zip(dph, plausible, strict=True)])
    assert c.counters["bad_lines"] == 0
    assert c.counters["implausible_samples"] == sum(ok and not p for (_, ok), p in zip(samples, plausible, strict=True))
