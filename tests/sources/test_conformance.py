"""Every source and every serial codec keeps the contract of fogmon.sources.base, checked
by one suite over all of them (python-can's ReaderWriterTest shape: the same tests,
one parameter per implementation)."""
from __future__ import annotations

import can
import numpy as np
import pytest
from helpers.fake_device import MAX_RATE_DPH, stream

from fogmon.block import Block
from fogmon.formats.capture import CAPTURE_FORMAT, write_sidecar
from fogmon.formats.replay_log import write_replay_log
from fogmon.sim.model import Noise, SensorModel, save_model
from fogmon.sources.base import CaptureSource, Codec, Source
from fogmon.sources.codecs.can import load_dbc
from fogmon.sources.codecs.protocols import PROTOCOLS, codec_from_options, make_codec
from fogmon.sources.devices.can_bus import CanSource
from fogmon.sources.devices.serial_port import SerialSource
from fogmon.sources.open import open_replay_source
from fogmon.sources.options import SourceOptions

FS = 100.0


def _replay_log(tmp_path):
    t = np.arange(300) / FS
    t = np.delete(t, [50, 51])                                    # a gap: two placeholders
    write_replay_log(tmp_path / "run.csv", t, 3.0 + np.sin(t), {"temp_c": 20 + 0 * t}, {"sample_rate_hz": FS})
    return open_replay_source(str(tmp_path / "run.csv")), 300


def _archive_pieces(tmp_path):
    t = np.arange(400) / FS
    for k, sl in ((1, slice(0, 200)), (2, slice(200, 400))):
        write_replay_log(tmp_path / f"samples-000{k}.csv", t[sl], np.cos(t[sl]), {}, {"sample_rate_hz": FS, "piece": k})
    return open_replay_source(str(tmp_path)), 400


def _raw_capture(tmp_path):
    data, intact = stream(250, {100: "corrupt", 101: "drop"})
    path = tmp_path / "raw.bin"
    path.write_bytes(data)
    write_sidecar(str(path), {"format": CAPTURE_FORMAT, "kind": "serial", "protocol": "kvh-a", "kvh_rot": "rate",
                              "kvh_units": "deg", "sample_rate_hz": 1000.0, "max_rate_dph": MAX_RATE_DPH})
    return open_replay_source(str(path)), 250


def _can_log(tmp_path):
    from helpers.can_gyro import DBC, gyro_msgs

    path = str(tmp_path / "gyro.asc")
    with can.ASCWriter(path) as log:
        for m in gyro_msgs(range(120), extra=True):
            log.on_message_received(m)
    return open_replay_source(path, SourceOptions(dbc=DBC)), 120


def _model(tmp_path):
    p = tmp_path / "m.toml"
    save_model(SensorModel(FS, 1.0, Noise(N_dpsh=0.05)), p)
    from fogmon.sources.devices.simulated import SimulatedSource
    return SimulatedSource(str(p), duration_s=5.0, seed=3), 500


def _imu_samples():
    """(stamps s, rate deg/h, kept) of 300 samples at FS, two missing: a three-axis IMU file
    of tests/helpers/recordings.py's writers."""
    t = np.arange(300) / FS
    keep = np.ones(300, bool)
    keep[50:52] = False
    return t, 3.0 + np.sin(t), keep


def _ros_bag(tmp_path):
    from helpers.recordings import write_imu_bag

    write_imu_bag(tmp_path / "run.bag", *_imu_samples(), "ros1")
    return open_replay_source(str(tmp_path / "run.bag")), 300


def _px4_ulog(tmp_path):
    from helpers.recordings import write_ulog

    write_ulog(tmp_path / "flight.ulg", *_imu_samples())
    return open_replay_source(str(tmp_path / "flight.ulg")), 300


SOURCES = {"replay-log": _replay_log, "archive-pieces": _archive_pieces, "raw-capture": _raw_capture,
           "can-log": _can_log, "simulation": _model, "ros-bag": _ros_bag,
           "px4-ulog": _px4_ulog}


@pytest.fixture(params=sorted(SOURCES))
def finite_source(request, tmp_path):
    return SOURCES[request.param](tmp_path)


def _check_block(b: Block, sample_rate_hz: float) -> None:
    assert isinstance(b, Block)
    assert b.t_s.dtype == np.float64 and b.rate_dph.dtype == np.float64 and b.valid.dtype == bool
    assert len(b.t_s) == len(b.rate_dph) == len(b.valid)
    assert all(len(v) == len(b) for v in b.aux.values())
    if len(b) > 1:
        np.testing.assert_allclose(np.diff(b.t_s) * sample_rate_hz, 1.0, atol=1e-6)     # on the uniform grid
    assert np.all(np.isfinite(b.rate_dph[b.valid]))                               # invalid = placeholders


class TestFiniteSources:
    """Replays and bounded simulations."""

    def test_declares_what_the_pipeline_reads(self, finite_source):
        src, n = finite_source
        assert isinstance(src.name, str) and src.name
        assert isinstance(src.sample_rate_hz, float) and src.sample_rate_hz > 0
        assert src.n_samples == n
        assert all(isinstance(v, int) for v in src.counters.values())
        assert not isinstance(src, CaptureSource)
        assert src.live is False and src.opened_s is None         # read at the reader's pace
        src.limit(n // 2)                                         # the pipeline cuts a file itself
        _typed: Source = src  # noqa: F841  (mypy checks the protocol)

    def test_blocks_cover_the_grid_once(self, finite_source):
        src, n = finite_source
        blocks = list(src.blocks())
        for b in blocks:
            _check_block(b, src.sample_rate_hz)
            assert b.axes == src.axes                                                    # as declared
        t = np.concatenate([b.t_s for b in blocks])
        assert len(t) == n
        np.testing.assert_allclose(np.diff(t) * src.sample_rate_hz, 1.0, atol=1e-6)    # across blocks too

    def test_close_ends_blocks(self, finite_source):
        src, n = finite_source
        it = src.blocks()
        first = next(it)
        src.close()
        assert sum(len(b) for b in it) + len(first) <= n


# -- live sources: declared interface (the devices themselves: sources/test_serial, test_can) --------
def test_live_sources_are_capture_sources_with_no_length():
    from helpers.can_gyro import DBC

    serial_src = SerialSource("loop://", 921600, make_codec("kvh-a"))
    can_src = CanSource("conformance", "virtual", load_dbc(DBC), dbc_path=DBC)
    for src in (serial_src, can_src):
        assert isinstance(src, CaptureSource) and src.n_samples is None and src.sample_rate_hz > 0
        assert src.live is True and src.opened_s is None                  # not opened yet
        _typed: Source = src  # noqa: F841
        spec = src.capture_spec()
        assert spec["kind"] in ("serial", "can") and src.pending == 0
        assert all(isinstance(v, int) for v in src.counters.values())


# -- codecs -------------------------------------------------------------------------------
CODEC_INPUT = {
    "kvh-a": stream(40)[0], "kvh-b": stream(40, fmt="b")[0], "kvh-c": stream(40, fmt="c")[0],
    "dsp3000": b"".join(b"%.4f 1\r\n" % (0.01 * k) for k in range(40)),
    "lines": b"".join(b"%d,%.3f\n" % (k, 1.5 * k) for k in range(40)),
}
CODEC_OPTIONS = {"kvh-a": {"kvh_rot": "rate", "kvh_units": "deg", "max_rate_dph": MAX_RATE_DPH},
                 "kvh-b": {"kvh_rot": "rate", "kvh_units": "deg", "max_rate_dph": MAX_RATE_DPH},
                 "kvh-c": {"kvh_rot": "rate", "kvh_units": "deg", "max_rate_dph": MAX_RATE_DPH},
                 "dsp3000": {}, "lines": {"columns": "seq,rate_dph"}}


@pytest.fixture(params=PROTOCOLS)
def protocol(request):
    return request.param


def _codec(protocol: str) -> Codec:
    return make_codec(protocol, **CODEC_OPTIONS[protocol])


class TestCodecs:
    def test_declares_the_codec_interface(self, protocol):
        c = _codec(protocol)
        assert c.protocol == protocol and c.sample_rate_hz > 0 and isinstance(c.aux_names, tuple)
        assert c.seq_modulus is None or c.seq_modulus >= 2
        assert isinstance(c.describe(), str) and c.pending == 0

    def test_any_chunking_decodes_alike(self, protocol):
        data = CODEC_INPUT[protocol]
        whole = _codec(protocol).feed(data)
        c = _codec(protocol)
        parts = [c.feed(data[i:i + 7]) for i in range(0, len(data), 7)]
        rate = np.concatenate([p.rate_dph for p in parts])
        assert len(whole) >= 30
        np.testing.assert_array_equal(rate, whole.rate_dph)
        assert c.pending == 0 and c.counters["frames_ok"] == len(whole)

    def test_options_rebuild_the_same_decoder(self, protocol):
        data = CODEC_INPUT[protocol]
        c = _codec(protocol)
        again = codec_from_options(c.options())
        assert again.options() == c.options()
        np.testing.assert_array_equal(again.feed(data).rate_dph, c.feed(data).rate_dph)

    def test_a_partial_frame_is_pending_not_lost(self, protocol):
        data = CODEC_INPUT[protocol]
        c = _codec(protocol)
        cut = len(data) // 2 + 3
        n1 = len(c.feed(data[:cut]))
        assert 0 < c.pending < cut
        n2 = len(c.feed(data[cut:]))
        assert n1 + n2 == len(_codec(protocol).feed(data))
