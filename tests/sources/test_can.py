"""CAN gyro on python-can virtual buses with the example DBC: decoding, counter gap
detection, invalid/undecodable/foreign frames; logs written by python-can's own Logger
(.asc .blf .csv .log .trc) replayed; the archive's CAN capture replays to the same
samples."""
import threading
import time
import uuid

import can
import numpy as np
import pytest
from helpers.can_gyro import DBC, FS, gyro_msgs
from helpers.doubles import args_for
from hypothesis import given, settings, strategies as st

from fogmon.errors import FogmonError
from fogmon.formats.replay_log import read_replay_log
from fogmon.pipeline import PipelineConfig, run_pipeline
from fogmon.sinks.archive import Archive
from fogmon.sources.codecs.can import CanDecoder, load_dbc
from fogmon.sources.devices.can_bus import CanSource
from fogmon.sources.open import open_live_source, open_replay_source


def gather(source):
    bl = list(source.blocks())

    def cat(f):
        return np.concatenate([f(b) for b in bl])

    return bl, cat(lambda b: b.t_s), cat(lambda b: b.rate_dph), cat(lambda b: b.valid), cat(lambda b: b.aux["temp_c"])


def test_decoder_defaults_from_dbc():
    d = CanDecoder(load_dbc(DBC))
    signals = (d.rate_signal, d.temp_signal, d.counter_signal, d.valid_signal)
    assert signals == ("rate", "temperature", "counter", "valid")
    assert d.sample_rate_hz == FS and d.seq_modulus == 16 and d.rate_unit == "deg/s"


@pytest.mark.parametrize("kw,msg", [({"message": "NOPE"}, "^can_message 'NOPE'"),
                                    ({"rate_signal": "omega"}, "^can_rate 'omega'"),
                                    ({"temp_signal": "t"}, "^can_temp 't'"),
                                    ({"rate_unit": "furlong/s"}, "unit 'furlong/s'")])
def test_decoder_option_errors_are_one_line(kw, msg):
    with pytest.raises(FogmonError, match=msg) as e:
        CanDecoder(load_dbc(DBC), **kw)
    assert "\n" not in str(e.value)


def test_live_can_needs_dbc_and_bad_dbc_is_one_line(tmp_path):
    with pytest.raises(FogmonError, match="^can needs dbc F"):
        open_live_source(args_for("--can", "x", "--interface", "virtual"))
    bad = tmp_path / "bad.dbc"
    bad.write_text("BO_ nonsense\n")
    with pytest.raises(FogmonError, match="not a valid DBC") as e:
        load_dbc(str(bad))
    assert "\n" not in str(e.value)


def test_virtual_bus_live_source_exact_accounting():
    ch = f"fogmon-{uuid.uuid4().hex}"
    src = open_live_source(args_for("--can", ch, "--interface", "virtual", "--dbc", DBC))
    ks = [k for k in range(120) if k not in (10, 11, 12, 60)]
    msgs = gyro_msgs(ks, invalid=(30,))
    done = threading.Event()

    def device():
        while src._thread is None:
            time.sleep(0.005)
        with can.Bus(interface="virtual", channel=ch, preserve_timestamps=True) as tx:
            for m in msgs:
                tx.send(m)
                time.sleep(0.001)
        done.set()

    th = threading.Thread(target=device)
    th.start()
    blocks = []
    for b in src.blocks():
        blocks.append(b)
        if done.is_set() and sum(len(x) for x in blocks) >= 120:
            break
    src.close()
    th.join()
    t = np.concatenate([b.t_s for b in blocks])
    rate = np.concatenate([b.rate_dph for b in blocks])
    valid = np.concatenate([b.valid for b in blocks])
    assert len(t) == 120 and np.allclose(t, np.arange(120) / FS)
    good = [k for k in ks if k != 30]
    np.testing.assert_allclose(rate[valid], 3.6 * np.array(good), rtol=1e-9)
    np.testing.assert_array_equal(np.flatnonzero(valid), good)
    c = src.counters
    assert c["frames_ok"] == len(ks) and c["bad_frames"] == 1 and c["other_frames"] == 1
    assert c["seq_gaps"] == 2 and c["samples_missing"] == 4 and c["invalid_samples"] == 1


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".csv", ".log", ".trc"])
def test_can_logs_written_by_python_can_replay_exactly(tmp_path, suffix):
    # frames 50..149 lost: a 1 s outage, longer than the counter wrap (16 frames = 0.16 s)
    ks = [k for k in range(300) if not (50 <= k < 150) and k != 200]
    path = str(tmp_path / f"gyro{suffix}")
    with can.Logger(path) as log:
        for m in gyro_msgs(ks):
            log.on_message_received(m)
    src = open_replay_source(path, args_for("--dbc", DBC))
    assert src.n_samples == 300
    _, t, rate, valid, temp = gather(src)
    assert len(t) == 300 and np.allclose(t, np.arange(300) / FS)
    np.testing.assert_array_equal(np.flatnonzero(valid), ks)
    np.testing.assert_allclose(rate[valid], 3.6 * np.array(ks), rtol=1e-9)
    np.testing.assert_allclose(temp[valid], 20 + 0.01 * np.array(ks), atol=1e-9)
    c = src.counters
    assert c["samples_missing"] == 101 and c["seq_gaps"] == 2 and c["frames_ok"] == len(ks)


def test_can_log_without_dbc_is_one_line_error(tmp_path):
    path = str(tmp_path / "g.asc")
    with can.Logger(path) as log:
        for m in gyro_msgs(range(3)):
            log.on_message_received(m)
    with pytest.raises(FogmonError, match="needs dbc F"):
        open_replay_source(path, args_for())


def test_archive_of_can_source_replays_to_the_same_samples(tmp_path):
    ch = f"fogmon-{uuid.uuid4().hex}"
    src = CanSource(ch, "virtual", load_dbc(DBC), dbc_path=DBC)
    archive = Archive(str(tmp_path / "arch"), src)
    ks = [k for k in range(150) if k not in (20, 21, 99)]

    def device():
        while src._thread is None:
            time.sleep(0.005)
        with can.Bus(interface="virtual", channel=ch, preserve_timestamps=True) as tx:
            for m in gyro_msgs(ks, t0=time.time(), invalid=(40,)):
                tx.send(m)
                time.sleep(0.0005)
        t_end = time.monotonic() + 30      # stop once every frame sent has been decoded
        while src.counters["frames_ok"] < len(ks) and time.monotonic() < t_end:
            time.sleep(0.005)
        src.close()                        # the pipeline still delivers what was decoded

    th = threading.Thread(target=device)
    th.start()
    run_pipeline(src, PipelineConfig(window_s=0.64, keep_motion=True), [archive])
    th.join()
    rec = read_replay_log(archive.replay_log_path)
    assert len(rec) == len(ks) - 1
    np.testing.assert_allclose(rec.t_s * FS, [k for k in ks if k != 40], atol=1e-6)
    assert rec.meta["sample_rate_hz"] == "100"
    # frames.asc + sidecar + the DBC copy: no --dbc needed
    rep = open_replay_source(archive.capture_path, args_for())
    _, t, rate, valid, _ = gather(rep)
    np.testing.assert_allclose(t[valid], rec.t_s, rtol=1e-11)        # the log keeps 12 significant digits
    np.testing.assert_allclose(rate[valid], rec.rate_dph, rtol=1e-11)


def test_decoder_gates_rates_beyond_max_rate_dph():
    d = CanDecoder(load_dbc(DBC), max_rate_dph=100.0)      # frame k carries 3.6 k deg/h
    (brk, f), = d.feed(gyro_msgs(range(40), invalid=(35,), extra=False))
    assert brk is None and list(np.flatnonzero(np.isfinite(f.rate_dph))) == list(range(28))
    assert d.counters["implausible_samples"] == 11                 # 28..39 but the flagged-invalid 35
    assert d.options()["max_rate_dph"] == 100.0
    assert CanDecoder(load_dbc(DBC)).max_rate_dph == 36_000_000    # generic: the DBC range +-2147 deg/s is inside


def test_can_log_gate_from_its_sidecar_or_the_command_line(tmp_path):
    import json
    import shutil
    path = tmp_path / "frames.asc"
    with can.Logger(str(path)) as log:
        for m in gyro_msgs(range(60), extra=False):
            log.on_message_received(m)
    shutil.copy(DBC, tmp_path / "gyro.dbc")
    (tmp_path / "frames.asc.json").write_text(json.dumps({"format": "fogmon capture v1", "kind": "can",
                                                          "dbc": "gyro.dbc", "max_rate_dph": 100.0}))
    for argv, n_ok in (((), 28), (("--max-rate-dph", "180"), 51), (("--max-rate-dph", "1e6"), 60)):
        src = open_replay_source(str(path), args_for(*argv))
        _, _, rate, valid, _ = gather(src)
        assert int(valid.sum()) == n_ok and np.isnan(rate[~valid]).all()
        assert src.counters["implausible_samples"] == 60 - n_ok


class FlakyBus:
    """A bus that delivers its frames, then fails (adapter unplugged)."""

    def __init__(self, msgs, fail_at_end):
        self.msgs, self.fail = list(msgs), fail_at_end

    def recv(self, timeout=None):
        if self.msgs:
            return self.msgs.pop(0)
        if self.fail:
            raise can.CanOperationError("adapter gone")
        time.sleep(timeout or 0)
        return None

    def shutdown(self):
        pass


def test_can_adapter_lost_and_back_outage_measured_by_timestamps():
    src = CanSource("x", "virtual", load_dbc(DBC), backoff_s=(0.01, 0.05))
    # frames 0..99, adapter lost for 1.5 s (frames 100..249 never seen), frames 250..299
    buses = [FlakyBus(gyro_msgs(range(100), extra=False), True),
             FlakyBus(gyro_msgs(range(250, 300), extra=False), False)]
    attempts = []

    def opener():
        attempts.append(1)
        if len(attempts) == 2:
            raise can.CanInitializationError("not yet")   # first retry fails: backoff
        return buses.pop(0)

    src._open = opener
    blocks, t_end = [], time.monotonic() + 10
    for b in src.blocks():
        blocks.append(b)
        if sum(len(x) for x in blocks) >= 300 or time.monotonic() > t_end:
            break
    src.close()
    valid = np.concatenate([b.valid for b in blocks])
    rate = np.concatenate([b.rate_dph for b in blocks])
    assert len(valid) == 300 and valid[:100].all() and not valid[100:250].any() and valid[250:].all()
    np.testing.assert_allclose(rate[valid], 3.6 * np.r_[0:100, 250:300])
    kinds = [e.kind for b in blocks for e in b.events]
    assert kinds.count("disconnect") == 1 and kinds.count("reconnect") == 1 and "gap" in kinds
    assert src.counters["disconnects"] == 1 and src.counters["reconnects"] == 1 and len(attempts) == 3
    assert src.counters["samples_missing"] == 150


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([0x100, 0x101, 0x200]), st.binary(max_size=8),
                          st.floats(0, 1e3, allow_nan=False)), max_size=40))
def test_property_can_decoder_never_raises_and_accounts(frames):
    d = CanDecoder(load_dbc(DBC))
    msgs = [can.Message(timestamp=ts, arbitration_id=i, is_extended_id=False, data=data) for i, data, ts in
            sorted(frames, key=lambda f: f[2])]
    segs = d.feed(msgs)
    n = sum(len(f) for _, f in segs)
    c = d.counters
    assert n == c["frames_ok"] and c["frames_ok"] + c["bad_frames"] + c["other_frames"] == len(msgs)
    assert all(np.isfinite(f.rate_dph).all() and ((f.seq >= 0) & (f.seq < 16)).all() for _, f in segs)


def test_a_timestamp_jump_beyond_any_gap_is_a_one_line_error_not_an_allocation():
    """The adapter's timestamps jump by 10**9 s (1e11 samples at 100 Hz) between two
    frames: no sample grid bridges that; the run ends with one line naming the device."""
    msgs = gyro_msgs(range(50), extra=False) + gyro_msgs(range(50, 60), t0=1_000_000.0 + 1e9, extra=False)
    src = CanSource("x", "virtual", load_dbc(DBC))
    src._open = lambda: FlakyBus(msgs, False)
    n = 0
    with pytest.raises(FogmonError, match=r"^--can x --interface virtual: an outage of 1e\+11 samples .* the run ends"):
        for b in src.blocks():
            n += len(b)
    assert n == 50
