"""The Rerun sink: the .rrd read back holds exactly what the engine computed, and a live
gRPC receiver gets the same data as the file; --rotate-s pieces; the --serve server's
life (only where asked, never on a busy port, never outliving fogmon); no empty .rrd."""
from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO
from helpers.doubles import Collect, ListSource, white_noise as _white
from helpers.net import free_port, listening, wait_until
from helpers.rrd import read_column, read_scalars, read_texts, read_views, rgb
from rerun.chunk import RrdReader

from fogmon.block import Event
from fogmon.davar.batch import dadev
from fogmon.errors import FogmonError
from fogmon.pipeline import PipelineConfig as _args, run_pipeline
from fogmon.sinks.base import COEFFICIENTS, Summary
from fogmon.sinks.console import format_summary
from fogmon.sinks.rerun.columns import _Decimator
from fogmon.sinks.rerun.plots import NO_DATA_KEY, stacked_label_texts
from fogmon.sinks.rerun.server import start_grpc_server, stop_process_group
from fogmon.sinks.rerun.sink import RerunSink, event_text, model_span
from fogmon.sinks.rerun.style import aux_colour


@pytest.fixture(scope="module")
def run_rrd(tmp_path_factory):
    sample_rate_hz, n = 100.0, 40_000
    t, r = _white(n, sample_rate_hz, seed=7, t0=3.0)
    r[20_000:20_050] = np.nan
    temp = 25 + 0.001 * np.arange(n)
    ev = [Event(100.0, "crc_error", "frame 42: bad CRC")]
    path = str(tmp_path_factory.mktemp("rrd") / "run.rrd")
    src = ListSource(t, r, [7000] * 5 + [5000], sample_rate_hz, aux={"temp_c": temp}, events=ev)
    engine_out = Collect()
    summary = run_pipeline(src, _args(window_s=81.92, hop_s=10.24), sinks=[RerunSink(rrd_path=path), engine_out])
    return path, t, r, temp, summary, engine_out


def _cat(frames, get):
    return np.concatenate([np.atleast_1d(get(d, f, te)) for d, f, te in frames], axis=0)


def test_rrd_dadev_and_coefficients_equal_the_engine(run_rrd):
    path, t, r, _, summary, engine_out = run_rrd
    fr = engine_out.frames_
    ts, logadev = read_scalars(path, "/dadev/log10_adev_dph")
    adev = _cat(fr, lambda d, f, te: d.adev_dph)
    t_end = _cat(fr, lambda d, f, te: te)
    assert logadev.shape == adev.shape == (summary.n_windows, 12)  # 8192-sample windows: m = 1 .. 2048
    np.testing.assert_allclose(ts, t_end, atol=1e-9)
    np.testing.assert_allclose(10.0 ** logadev, adev, rtol=1e-14)
    # ... and the engine (streaming) agrees with the batch DADEV on the same input
    ref = dadev(r, 100.0, 81.92, 10.24, valid=np.isfinite(r), t0_s=3.0)
    np.testing.assert_allclose(adev, ref.adev_dph, rtol=1e-9)
    np.testing.assert_allclose(t_end, 3.0 + ref.end_index / 100.0, atol=1e-9)
    for name in COEFFICIENTS:
        v, lo, hi, ok = (_cat(fr, lambda d, f, te, a=a, name=name: np.asarray(getattr(getattr(f, name), a)))
                         for a in ("value", "lo", "hi", "identifiable"))
        ok = ok.astype(bool) & np.isfinite(v) & np.isfinite(lo) & np.isfinite(hi)
        tc, vals = read_scalars(path, f"/coef/{name}")
        assert len(tc) == int(ok.sum())
        if ok.any():
            np.testing.assert_allclose(tc, t_end[ok], atol=1e-9)
            np.testing.assert_array_equal(vals, np.column_stack([v[ok], lo[ok], hi[ok]]))
    assert len(read_scalars(path, "/coef/N_dpsh")[0]) == summary.n_windows  # white noise: N in every window


def test_rrd_raw_rate_aux_and_events(run_rrd):
    path, t, r, temp, _, _ = run_rrd
    tr, rate = read_scalars(path, "/rate/rate_dph")
    ok = np.isfinite(r)
    assert len(tr) == ok.sum()                      # 100 Hz: not decimated; gaps not drawn
    np.testing.assert_allclose(tr, t[ok], atol=1e-9)
    np.testing.assert_array_equal(rate[:, 0], r[ok])
    ta, tv = read_scalars(path, "/aux/temp_c")
    np.testing.assert_array_equal(tv[:, 0], temp)
    texts = read_texts(path, "/events")
    assert "100.00 s  crc_error: frame 42: bad CRC" in texts          # the recording time leads each message
    assert rgb(read_column(path, "/aux/temp_c", "SeriesLines:colors")[0][1][0]) == aux_colour(0)
    assert len(read_scalars(path, "/aux/temp_c/y_range")[0]) == 0      # one aux view: tall, its own range


def test_many_aux_channels_get_rounded_y_ranges(tmp_path):
    """More than three aux channels share two rows of small views: each gets its range
    so far rounded out to <= 3 steps of a power of ten (two labelled ticks)."""
    t, r = _white(3000, 10.0, seed=3)
    aux = {f"c{k}": np.linspace(0.0, 720.0 * (k + 1), 3000) for k in range(4)}
    path = str(tmp_path / "aux.rrd")
    run_pipeline(ListSource(t, r, [1000] * 3, 10.0, aux=aux), _args(window_s=51.2, hop_s=12.8),
                 sinks=[RerunSink(rrd_path=path)])
    for k, v in enumerate(aux.values()):
        _, frames = read_scalars(path, f"/aux/c{k}/y_range")
        lo, hi = frames[-1]
        assert lo <= v.min() and v.max() <= hi and round((hi - lo) / 10 ** np.floor(np.log10(hi - lo))) <= 3
    assert tuple(read_scalars(path, "/aux/c0/y_range")[1][-1]) == (0.0, 1000.0)


def test_event_text_leads_with_the_time_and_says_the_kind_once():
    assert event_text(Event(8.96, "platform_motion", "platform motion ended: 1 .. 2 s")) == (
        "8.96 s  platform motion ended: 1 .. 2 s")
    assert event_text(Event(1234.5, "coef_jump", "N_dpsh x2.0", axis="y"), of_axis=True) == (
        "1234.50 s  axis y: coef_jump: N_dpsh x2.0")


def _nice(lo, hi):
    """Whether lo..hi are multiples of a power of ten 1..6 steps of it apart."""
    for k in range(-12, 12):
        step = 10.0 ** k
        n = (hi - lo) / step
        if (abs(lo / step - round(lo / step)) < 1e-6 and abs(hi / step - round(hi / step)) < 1e-6
                and 1 - 1e-9 <= n <= 6 + 1e-9):
            return True
    return False


def test_coefficient_tracks_have_a_rounded_y_range_for_readable_ticks(run_rrd):
    """``coef/<name>/y_range``: at every window, invisible points at the range of all the
    track drew so far (value, interval, upper limits) rounded out to multiples of a power
    of ten (<= 6 steps), so Rerun labels the y axis; the tracks' views have no legend."""
    path = run_rrd[0]
    views = read_views(path)
    for name in COEFFICIENTS:
        t_v, v = read_scalars(path, f"/coef/{name}")
        t_u, u = read_scalars(path, f"/coef/{name}/upper_limit")
        t_r, r = read_scalars(path, f"/coef/{name}/y_range")
        assert len(t_r) and set(np.round(np.r_[t_v, t_u], 9)) <= set(np.round(t_r, 9))
        for t, (lo, hi) in zip(t_r, r, strict=True):
            drawn = np.r_[v[t_v <= t + 1e-9].ravel(), u[t_u <= t + 1e-9].ravel()]
            assert lo <= drawn.min() and drawn.max() <= hi and _nice(lo, hi), (name, t, lo, hi)
        colours = read_column(path, f"/coef/{name}/y_range", "SeriesPoints:colors")[0][1]
        assert all(c & 255 == 0 for c in colours)                     # alpha 0: invisible
        (view,) = [x for x in views.values() if x["origin"] == f"/coef/{name}"]
        assert view["props"]["PlotLegend"]["PlotLegend:visible"] == [False]


def test_rrd_coefficient_upper_limits_where_not_identifiable(run_rrd):
    """``coef/<name>/upper_limit`` holds the 95 % upper limit (``hi``) in exactly the
    windows where the coefficient is not identifiable, beside its interval elsewhere."""
    path, _, _, _, summary, engine_out = run_rrd
    fr = engine_out.frames_
    t_end = _cat(fr, lambda d, f, te: te)
    n_limits = 0
    for name in COEFFICIENTS:
        hi, ident = (_cat(fr, lambda d, f, te, a=a, name=name: np.asarray(getattr(getattr(f, name), a)))
                     for a in ("hi", "identifiable"))
        up = ~ident.astype(bool) & np.isfinite(hi)
        tu, vals = read_scalars(path, f"/coef/{name}/upper_limit")
        assert len(tu) == int(up.sum())
        if up.any():
            np.testing.assert_allclose(tu, t_end[up], atol=1e-9)
            np.testing.assert_array_equal(vals[:, 0], hi[up])
        n_limits += len(tu)
    assert n_limits > summary.n_windows      # white noise: B, K, R are upper limits in most windows
    names = read_column(path, "/coef/R_dphh/upper_limit", "SeriesPoints:names")
    assert names and names[0][1] == ["upper limit (not identifiable)"]


def test_rrd_model_line_only_over_the_fitted_taus(run_rrd):
    """The IEEE-952 model is drawn from the first to the last tau the fit used (measured,
    not flagged as misfit), never extrapolated to taus the fit left out."""
    path, engine_out = run_rrd[0], run_rrd[5]
    d, f, te = engine_out.frames_[-1]
    rows = read_column(path, "/adev_curve/log10/model_ieee952", "LineStrips2D:strips")
    t_last, strips = max(rows, key=lambda r: r[0])
    assert t_last == pytest.approx(te[-1], abs=1e-9)
    xy = np.array(strips[0])
    span = model_span(d.tau_s, d.adev_dph[-1], np.asarray(f.misfit)[-1])
    np.testing.assert_allclose([xy[0, 0], xy[-1, 0]], np.log10(span), atol=1e-6)
    np.testing.assert_allclose(xy[:, 1], np.log10(f.model_adev_dph(10.0 ** xy[:, 0])[-1]), atol=1e-5)


def test_model_span_leaves_out_misfit_and_unmeasured_taus():
    tau = np.array([0.01, 0.02, 0.04, 0.08, 0.16, 0.32])
    adev = np.array([40.0, 30.0, 20.0, 14.0, 10.0, np.nan])
    assert model_span(tau, adev, np.array([1, 1, 0, 1, 0, 0], dtype=bool)) == (0.04, 0.16)
    assert model_span(tau, adev, np.ones(6, dtype=bool)) is None


def test_rrd_heatmap_legend_and_labels(run_rrd):
    """The DADEV heatmap is a colour image of the latest windows (rows: taus) with tau
    and time labels in units, beside its colour scale labelled in deg/h (drawn once);
    the ADEV view has a legend."""
    path, engine_out = run_rrd[0], run_rrd[5]
    n_taus = len(engine_out.frames_[0][0].tau_s)
    n_windows = sum(len(te) for _, _, te in engine_out.frames_)
    images = read_column(path, "/dadev/heatmap/map/image", "Image:format")
    assert images and images[-1][1][0]["width"] == n_windows and images[-1][1][0]["height"] == n_taus
    labels = max(read_column(path, "/dadev/heatmap/labels", "Points2D:labels"), key=lambda r: r[0])[1]
    assert sum(x.endswith(" s") for x in labels) >= 6
    scale = read_column(path, "/dadev/heatmap/scale_labels", "Points2D:labels")   # fixed: drawn once, static
    assert len(scale) == 1 and scale[0][0] is None and scale[0][1] and all(x.endswith(" deg/h") for x in scale[0][1])
    key = read_column(path, "/dadev/heatmap/no_data_key", "Points2D:labels")    # the colour of NaN cells, keyed
    assert key == [(None, [NO_DATA_KEY])]
    legend = read_column(path, "/adev_curve/log10/legend", "Points2D:labels")[0][1]
    assert stacked_label_texts(legend) == ["measured ADEV, current window", "68.3 % confidence bounds",
                                           "IEEE-952 model (fitted taus)"]


def test_one_axis_layout(run_rrd):
    """A one-axis stream's views show its entities, each with its children: one view
    per aux channel, an event log of level and message only (the time leads the message)."""
    views = read_views(run_rrd[0]).values()
    assert sorted((v["class"], v["origin"]) for v in views) == sorted(
        [("TimeSeries", "/rate/rate_dph"), ("TimeSeries", "/aux/temp_c"), ("2D", "/adev_curve"),
         ("2D", "/dadev/heatmap"), ("TimeSeries", "/dadev/log10_adev_dph"),
         *(("TimeSeries", f"/coef/{n}") for n in COEFFICIENTS),
         ("TextLog", "/events"), ("TimeSeries", "/counters"), ("TextDocument", "/session")])
    assert all(v["contents"] == ["$origin/**"] for v in views)
    (log,) = [v for v in views if v["class"] == "TextLog"]
    cols = log["props"]["TextLogColumns"]
    assert [c["visible"] for c in cols["TextLogColumns:timeline_columns"]] == [False]
    assert [(c["kind"], c["visible"]) for c in cols["TextLogColumns:text_log_columns"]] == [(2, True), (3, True)]


def test_decimator_means_valid_samples_across_pushes():
    d = _Decimator(10)
    t = np.arange(35) / 1000.0
    v = np.arange(35, dtype=float)
    v[12] = np.nan
    d.push(t[:13], {"x": v[:13]})
    d.push(t[13:], {"x": v[13:]})
    tb, out = d.take()
    np.testing.assert_allclose(tb, [0.0, 0.010, 0.020])
    np.testing.assert_allclose(out["x"], [4.5, np.mean([10, 11, 13, 14, 15, 16, 17, 18, 19]), 24.5])
    tb, out = d.take(final=True)
    np.testing.assert_allclose(out["x"], [32.0])


def test_1khz_rate_is_decimated_for_display_only(tmp_path):
    sample_rate_hz = 1000.0
    t, r = _white(20_000, sample_rate_hz)
    path = str(tmp_path / "k.rrd")
    s = run_pipeline(ListSource(t, r, [4096] * 4 + [20_000 - 4 * 4096], sample_rate_hz), _args(window_s=4.096),
                     sinks=[RerunSink(rrd_path=path)])
    tr, rate = read_scalars(path, "/rate/rate_dph")
    assert len(tr) == 2000
    np.testing.assert_allclose(rate[:, 0], r.reshape(-1, 10).mean(axis=1), rtol=1e-12)
    _, logadev = read_scalars(path, "/dadev/log10_adev_dph")
    assert logadev.shape[0] == s.n_windows and logadev.shape[1] == 11   # m = 1, 2, .., 1024 = 4096 // 4


@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # a receiver killed mid-stream writes none
def test_live_grpc_receiver_gets_the_same_data_as_the_file(tmp_path):
    rerun_exe = shutil.which("rerun") or str(Path(sys.executable).parent / "rerun")
    port = free_port()
    live = str(tmp_path / "live.rrd")
    recv = subprocess.Popen([rerun_exe, "--bind", "127.0.0.1", "--port", str(port), "--save", live],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120  # a guard against a hang, not a timing
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "rerun receiver did not start"
                time.sleep(0.1)
        sample_rate_hz = 100.0
        t, r = _white(12_000, sample_rate_hz, seed=3)
        file_ = str(tmp_path / "file.rrd")
        run_pipeline(ListSource(t, r, [3000] * 4, sample_rate_hz), _args(window_s=20.48),
                     sinks=[RerunSink(rrd_path=file_, connect_url=f"rerun+http://127.0.0.1:{port}/proxy")])
        ents = ("/dadev/log10_adev_dph", "/coef/N_dpsh", "/rate/rate_dph")

        def received_all():           # the receiver saves as data arrives: wait for the data, not a time
            try:
                return all(len(read_scalars(live, e)[0]) == len(read_scalars(file_, e)[0]) for e in ents)
            except (OSError, ValueError, RuntimeError):  # RuntimeError: a frame still being written
                return False

        wait_until(received_all, "the live receiver did not get every row")
    finally:
        stop_process_group(recv)
    for ent in ents:
        tf, vf = read_scalars(file_, ent)
        tl, vl = read_scalars(live, ent)
        assert len(tf) > 0
        np.testing.assert_array_equal(tl, tf)
        np.testing.assert_array_equal(vl, vf)


@pytest.mark.parametrize("bind", ["127.0.0.1", "0.0.0.0"])
def test_serve_listens_only_where_asked(bind):
    port = free_port()
    proc, url = start_grpc_server(bind, port)
    try:
        assert url == f"rerun+http://127.0.0.1:{port}/proxy"
        assert listening(port) == {bind}
    finally:
        stop_process_group(proc)
    assert listening(port) == set()


def test_serve_on_a_busy_port_is_one_line_before_anything_starts(tmp_path):
    port = free_port()
    with socket.create_server(("127.0.0.1", port)):            # a stale server holds the port
        with pytest.raises(FogmonError, match=f"serve: port {port} on 127.0.0.1 is already in use"):
            RerunSink(rrd_path=str(tmp_path / "x.rrd"), serve=True, port=port)
        with pytest.raises(FogmonError, match="already in use"):
            RerunSink(serve=True, bind="0.0.0.0", port=port)    # the wildcard address conflicts too
    assert list(tmp_path.iterdir()) == []                       # the .rrd probe is gone


def test_the_server_dies_with_fogmon_even_on_sigkill(process_groups):
    """The rerun server is fogmon's own child (not the launcher's grandchild) with a death
    signal: SIGKILL of the process that started it frees the port."""
    port = free_port()
    code = ("import sys; from fogmon.sinks.rerun.server import start_grpc_server; "
            f"p, url = start_grpc_server('127.0.0.1', {port}); print(p.pid, flush=True); sys.stdin.read()")
    parent = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True, start_new_session=True)
    process_groups.append(parent)
    server_pid = int(parent.stdout.readline())
    assert listening(port) == {"127.0.0.1"}
    assert Path(f"/proc/{server_pid}/cmdline").read_bytes().split(b"\0")[1] == b"--serve-grpc"
    parent.kill()
    parent.wait()
    wait_until(lambda: not listening(port), "the server outlived its parent")
    wait_until(lambda: not os.path.exists(f"/proc/{server_pid}") or
               Path(f"/proc/{server_pid}/stat").read_text().split()[2] == "Z", "the server process is still there")


def test_the_program_writes_an_rrd_without_importing_pandas(tmp_path):
    """`fogmon replay --rrd` as the program runs it (its own process): Rerun's pyarrow
    arrays do not import pandas (0.3-0.45 CPU s of start-up, fogmon.startup)."""
    demo = REPO / "replay_logs" / "lasergyro_z_100hz.csv"
    rrd = tmp_path / "demo.rrd"
    code = ("import sys\nfrom fogmon.cli import main\n"
            f"sys.argv = ['fogmon', 'replay', {str(demo)!r}, '--rrd', {str(rrd)!r}, '--quiet', '--no-progress']\n"
            "rc = main()\nprint('pandas' in sys.modules)\nsys.exit(rc)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.splitlines()[-1] == "False" and rrd.stat().st_size > 0


def test_no_rrd_is_left_when_no_sample_came(tmp_path):
    fresh, kept = tmp_path / "new.rrd", tmp_path / "old.rrd"
    kept.write_bytes(b"an earlier recording")
    for path in (fresh, kept):
        sink = RerunSink(rrd_path=str(path))
        sink.finish(Summary("x", 10.0, 1.0, 1.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.rrd"] and kept.read_bytes() == b"an earlier recording"


@pytest.mark.filterwarnings("error:RRD file has no footer")
def test_rotated_rrd_pieces_are_complete_recordings_that_join(tmp_path):
    sample_rate_hz, n = 100.0, 40_000
    t, r = _white(n, sample_rate_hz, seed=9)
    one, rot = str(tmp_path / "one.rrd"), str(tmp_path / "rot.rrd")
    run_pipeline(
        ListSource(t, r, [7000] * 5 + [5000], sample_rate_hz), _args(window_s=40.96), sinks=[RerunSink(rrd_path=one)]
    )
    s = run_pipeline(ListSource(t, r, [7000] * 5 + [5000], sample_rate_hz), _args(window_s=40.96, rotate_s=100.0),
                     sinks=[RerunSink(rrd_path=rot, rotate=True)])
    pieces = [str(tmp_path / f"rot-000{k}.rrd") for k in range(1, 5)]
    assert sorted(str(p) for p in tmp_path.glob("rot-*.rrd")) == pieces
    assert s.outputs == [f"{pieces[0]} .. {pieces[-1]} (4 pieces)"]
    assert format_summary(s).endswith(f"Wrote {s.outputs[0]} (open them with: rerun {tmp_path}/rot-*.rrd)")
    assert len({e.recording_id for p in pieces for e in RrdReader(p).recordings()}) == 1   # the viewer joins them
    for k, piece in enumerate(pieces):
        tr, rate = read_scalars(piece, "/rate/rate_dph")
        np.testing.assert_allclose(tr, t[k * 10_000:(k + 1) * 10_000], atol=1e-8)  # its 100 s, every sample
        td, _ = read_scalars(piece, "/dadev/log10_adev_dph")
        assert len(td) and np.all((td >= 100 * k) & (td < 100 * (k + 1)))     # windows ending in it
        assert list(RrdReader(piece).stream().filter(content="/session", is_static=True))   # its own static data
    joined = [np.concatenate(x) for x in zip(*(read_scalars(p, "/dadev/log10_adev_dph") for p in pieces), strict=True)]
    t1, v1 = read_scalars(one, "/dadev/log10_adev_dph")
    np.testing.assert_array_equal(joined[0], t1)
    np.testing.assert_allclose(joined[1], v1, rtol=1e-12)       # blocks cut at the seams: same windows


def test_error_rate_is_logged_beside_the_raw_rate(tmp_path):
    sample_rate_hz = 10.0
    t, r = _white(4000, sample_rate_hz, seed=4)
    rot = np.where(t < 200, 0.0, 720.0)
    path = str(tmp_path / "e.rrd")
    run_pipeline(ListSource(t, r + 3600 * rot, [4000], sample_rate_hz, aux={"rot_dps": rot}), _args(window_s=51.2),
                 sinks=[RerunSink(rrd_path=path)])
    _, raw = read_scalars(path, "/rate/rate_dph")
    _, err = read_scalars(path, "/rate/error_dph")
    np.testing.assert_allclose(raw[:, 0], r + 3600 * rot)
    np.testing.assert_allclose(err[:, 0], r, atol=1e-9)
