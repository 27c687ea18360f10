"""The streaming pipeline: what the sinks receive equals the batch engine on the same data."""
from __future__ import annotations

import argparse
import io

import numpy as np
import pytest
from helpers.doubles import Collect, ListSource, white_noise as _white

from fogmon.block import Block, Event
from fogmon.cli.pipeline_options import parse_taus
from fogmon.davar.batch import dadev, oadev
from fogmon.davar.fit import fit_noise
from fogmon.pipeline import PipelineConfig, default_window_s, run_pipeline
from fogmon.sinks.base import COEFFICIENTS
from fogmon.sinks.console import ConsoleSink, format_summary
from fogmon.sources.pacing import Pacer


def _args(**kw):
    return PipelineConfig(**kw)


def test_frames_equal_batch_dadev_and_fit_with_gaps_and_odd_blocks():
    sample_rate_hz, n = 100.0, 30_000
    t, r = _white(n, sample_rate_hz, t0=12.5)
    r[5000:5037] = np.nan        # a gap: invalid placeholders
    sizes = [1, 999, 4096, 17, 8000, 3]
    sizes.append(n - sum(sizes))
    sink = Collect()
    src = ListSource(t, r, sizes, sample_rate_hz)
    summary = run_pipeline(src, _args(window_s=40.96, hop_s=5.12), sinks=[sink])
    ref = dadev(r, sample_rate_hz, 40.96, 5.12, valid=np.isfinite(r), t0_s=12.5)
    got = np.concatenate([d.adev_dph for d, _, _ in sink.frames_])
    t_end = np.concatenate([te for _, _, te in sink.frames_])
    assert got.shape == ref.adev_dph.shape == (len(ref), len(ref.tau_s))
    np.testing.assert_allclose(got, ref.adev_dph, rtol=1e-9)
    np.testing.assert_allclose(t_end, 12.5 + ref.end_index / sample_rate_hz, rtol=0, atol=1e-9)
    ref_fit = fit_noise(ref)
    for name in COEFFICIENTS:
        v = np.concatenate([np.atleast_1d(getattr(f, name).value) for _, f, _ in sink.frames_])
        np.testing.assert_allclose(v, getattr(ref_fit, name).value, rtol=1e-6, atol=1e-12)
    assert summary.n_samples == n and summary.n_invalid == 37 and summary.n_windows == len(ref)
    assert src.closed and sink.summary is summary
    ov = oadev(r, sample_rate_hz, valid=np.isfinite(r))
    np.testing.assert_allclose(summary.overall.adev_dph, ov.adev_dph, rtol=1e-12)  # the same batch call
    np.testing.assert_allclose(sink.info.tau_s, ref.tau_s)


def test_default_window_is_a_power_of_two_quarter_of_the_record():
    assert default_window_s(100.0, 184_718) == 32768 / 100.0
    assert default_window_s(1000.0, 3_600_000) == 2**19 / 1000.0
    assert default_window_s(1000.0, 10**9) == 2**20 / 1000.0
    assert default_window_s(100.0, 2000) == 1024 / 100.0      # the minimum
    assert default_window_s(100.0, 500) == 500 / 100.0        # never longer than the record
    assert default_window_s(1000.0, None) == 65.536           # live


def test_parse_taus():
    assert parse_taus("octave") == "octave" and parse_taus("8") == 8
    np.testing.assert_array_equal(parse_taus("0.1,1,10"), [0.1, 1, 10])
    with pytest.raises(argparse.ArgumentTypeError):
        parse_taus("1,x")
    with pytest.raises(argparse.ArgumentTypeError):
        parse_taus("-1")


def test_duration_stops_at_exact_sample_count_and_interrupt_is_clean():
    sample_rate_hz, n = 200.0, 20_000
    t, r = _white(n, sample_rate_hz)
    sink = Collect()
    s = run_pipeline(
        ListSource(t, r, [3000] * 6 + [2000], sample_rate_hz), _args(duration_s=12.0, window_s=2.0), sinks=[sink]
    )
    assert s.n_samples == 2400 and not s.interrupted
    assert sum(len(b) for b in sink.blocks) == 2400
    s = run_pipeline(
        ListSource(t, r, [3000] * 6 + [2000], sample_rate_hz), _args(duration_s=15.0, window_s=2.0), sinks=[sink]
    )
    assert s.n_samples == 3000                           # ends exactly on a block boundary
    src = ListSource(t, r, [3000] * 6 + [2000], sample_rate_hz, interrupt_after=2)
    s = run_pipeline(src, _args(window_s=2.0), sinks=[sink])
    assert s.interrupted and s.n_samples == 6000 and src.closed and sink.summary is s
    np.testing.assert_allclose(s.overall.adev_dph, oadev(r[:6000], sample_rate_hz).adev_dph, rtol=1e-12)


def test_realtime_paces_recording_time():
    sample_rate_hz = 100.0
    t, r = _white(100, sample_rate_hz)  # 1 s of recording, paced at 2x: pieces of 0.1 s wall = 20 samples
    now = [100.0]

    def sleep(d):                         # a clock that advances only by the pacer's sleeps
        now[0] += d

    class Clock(Collect):
        def block(self, b):
            self.blocks.append((now[0], float(b.t_s[-1]), len(b)))

    sink = Clock()
    run_pipeline(ListSource(t, r, [100], sample_rate_hz), _args(window_s=0.32, realtime=2.0), sinks=[sink],
                 pacer=Pacer(2.0, clock=lambda: now[0], sleep=sleep))
    assert [n for _, _, n in sink.blocks] == [20] * 5
    for wall, t_end, _ in sink.blocks:  # each piece when it is due at 2x real time, not before
        assert wall - 100.0 == pytest.approx(t_end / 2.0, abs=1e-9)


def test_events_pass_through_and_slice_keeps_them():
    sample_rate_hz = 100.0
    t, r = _white(3000, sample_rate_hz)
    ev = [Event(5.0, "crc_error", "bad CRC"), Event(17.3, "gap", "3 samples lost")]
    sink = Collect()
    s = run_pipeline(
        ListSource(t, r, [1000, 1000, 1000], sample_rate_hz, events=ev), _args(window_s=5.12), sinks=[sink]
    )
    assert [e.kind for e in sink.events_ if e.kind != "coef_jump"] == ["crc_error", "gap"]
    assert s.event_counts["crc_error"] == 1 and s.event_counts["gap"] == 1
    b = Block.make(t[:10], r[:10], events=[Event(t[3], "gap", "x")])
    assert b.slice(0, 3).events == () and len(b.slice(3, 10).events) == 1


def test_console_summary_lists_adev_bounds_and_coefficients():
    sample_rate_hz = 100.0
    t, r = _white(20_000, sample_rate_hz)
    buf = io.StringIO()
    s = run_pipeline(ListSource(t, r, [20_000], sample_rate_hz), _args(window_s=40.96),
                     sinks=[ConsoleSink(out=buf, err=io.StringIO())])
    text = buf.getvalue()
    assert text == format_summary(s) + "\n"
    assert "tau_s" in text and "lo_dph" in text and "hi_dph" in text
    a = s.overall
    assert f"{a.adev_dph[0]:12.5g}" in text and f"{a.hi_dph[-1]:12.5g}" in text
    n = s.overall_fit.N_dpsh
    assert bool(n.identifiable) and f"N_dpsh    = {float(n.value):.4g} deg/sqrt(h)" in text
    assert abs(float(n.value) - 0.05) < 0.005      # the simulated white noise, N = 0.05 deg/sqrt(h)


def test_reference_rotation_is_subtracted_unless_raw_rate():
    sample_rate_hz, n = 100.0, 16_384
    t, r = _white(n, sample_rate_hz, seed=9)
    rot = np.where(t < 80, 0.0, 720.0)                  # string starts turning at 80 s (720 deg/s)
    rot[100:105] = np.nan  # reference unknown: those samples are invalid
    meas = r + 3600.0 * np.nan_to_num(rot)
    sink = Collect()
    s = run_pipeline(
        ListSource(t, meas, [4096] * 4, sample_rate_hz, aux={"rot_dps": rot}), _args(window_s=40.96), sinks=[sink]
    )
    assert s.analysed == "rate_dph - 3600 x rot_dps" and sink.info.analysed == s.analysed
    err = meas - 3600.0 * rot
    ref = dadev(err, sample_rate_hz, 40.96, 40.96 / 8, valid=np.isfinite(err))
    np.testing.assert_allclose(np.concatenate([d.adev_dph for d, _, _ in sink.frames_]), ref.adev_dph, rtol=1e-9)
    s = run_pipeline(
        ListSource(t, meas, [4096] * 4, sample_rate_hz, aux={"rot_dps": rot}),
        _args(window_s=40.96, raw_rate=True),
        sinks=[Collect()],
    )
    assert s.analysed == "rate_dph" and [(m.t_start_s, m.t_end_s) for m in s.motion_spans] == [(79.68, 163.83)]
    assert np.isnan(s.overall.adev_dph[-1])     # the turning string is platform motion: kept out ...
    s = run_pipeline(ListSource(t, meas, [4096] * 4, sample_rate_hz, aux={"rot_dps": rot}),
                     _args(window_s=40.96, raw_rate=True, keep_motion=True), sinks=[Collect()])
    assert s.motion_spans == [] and s.overall.adev_dph[-1] > 1e5   # ... unless asked: the 2.6e6 deg/h step


def test_adev_tables_print_no_interval_below_one_edf():
    from types import SimpleNamespace

    from fogmon.davar.confidence import chi2_bounds
    from fogmon.sinks.console import adev_axes_lines, adev_lines

    adev, edf = np.array([2.0, 21.341]), np.array([50.0, 0.07])
    lo, hi = chi2_bounds(adev, edf)
    a = SimpleNamespace(tau_s=np.array([1.0, 16.48]), adev_dph=adev, lo_dph=lo, hi_dph=hi, edf=edf,
                        n_terms=np.array([100, 3]))
    lines = adev_lines(a)
    assert lines[2].split() == ["16.48", "21.341", "-", "-", "0.07", "3"]
    assert lines[-1].startswith("  no interval: EDF below 1")
    side = adev_axes_lines({"x": a, "y": a})
    assert side[2].split() == ["16.48", "21.341", "[no", "interval]", "21.341", "[no", "interval]"]
    assert side[-1] == lines[-1]
    a.edf, a.lo_dph, a.hi_dph = np.array([50.0, 2.0]), *chi2_bounds(adev, np.array([50.0, 2.0]))
    assert not adev_lines(a)[-1].startswith("  no interval")
    # a sample beyond the engine's ceiling (a gate set above it): inf, and why, not "EDF below 1"
    a.adev_dph, a.lo_dph, a.hi_dph = np.array([np.inf, 21.341]), *chi2_bounds(np.array([np.inf, 21.341]), a.edf)
    note = adev_lines(a)[-1]
    assert note.startswith("  inf: an Allan term at that tau spans a sample beyond 1e+08 deg/h") and \
        not any(x.startswith("  no interval") for x in adev_lines(a))
    a.adev_dph, a.lo_dph, a.hi_dph = np.zeros(2), np.zeros(2), np.zeros(2)     # a stuck output
    assert adev_lines(a)[-1].startswith("  the rate never changes (every Allan deviation is 0)")


def test_model_check_is_a_chi_square_test_with_each_taus_edf():
    from types import SimpleNamespace

    from fogmon.sinks.console import model_check

    a = SimpleNamespace(tau_s=np.array([1.0, 10.0, 100.0]), adev_dph=np.array([1.0, 0.32, 0.2]),
                        edf=np.array([1e4, 1e3, 4.0]))
    good = SimpleNamespace(check_adev_dph=lambda tau: np.array([1.0, 0.31623, 0.2]), misfit=np.zeros(3, bool))
    assert model_check(a, good) == ("  model check: the fitted model agrees with the measured ADEV within chance at "
                                    "every tau (chi-square with each tau's EDF, family-wise 1 % over 3 taus; largest "
                                    "factor 1.01 at tau 10 s)")
    # 1.5x at an EDF of 4 is chance (the old fixed 1.5x threshold warned); 1.1x at an EDF of 1e4 is not
    chance = SimpleNamespace(check_adev_dph=lambda tau: np.array([1.0, 0.32, 0.3]), misfit=np.zeros(3, bool))
    assert "WARNING" not in model_check(a, chance)
    bad = SimpleNamespace(check_adev_dph=lambda tau: np.array([1.1, 0.32, 0.2]), misfit=np.zeros(3, bool))
    msg = model_check(a, bad)
    assert msg.startswith("  model check: WARNING the fitted model departs from the measured ADEV beyond chance "
                          "(chi-square with each tau's EDF, family-wise 1 % over 3 taus) at tau 1 s (model 1.1x "
                          "above, p ")
    # a departure below 0.5 % at a huge EDF (a ramp-dominated tau) is beyond chance: its factor is
    # printed with the digits that show it, not as "1x"
    a.edf = np.array([1e6, 1e3, 4.0])
    small = SimpleNamespace(check_adev_dph=lambda tau: np.array([0.996, 0.32, 0.2]), misfit=np.zeros(3, bool))
    assert "at tau 1 s (model 1.004x below, p " in model_check(a, small)
