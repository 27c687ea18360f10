"""Rerun sink: the monitor's screen, live (gRPC) and/or headless (.rrd), rerun-sdk 0.41.

Everything is on the ``time`` timeline = recording time in s (not wall clock; Rerun's
``log_time`` is off), sent in columns (``send_columns``) once per flush (FLUSH_WALL_S), so
a 1 kHz gyro costs a few Python calls per flush and a replay a few per entity.
Entities (units in every name; "log10" said where the value is a log):

- ``rate/rate_dph`` raw rate in deg/h (and ``rate/error_dph`` = rate_dph - 3600 x rot_dps,
  what DAVAR analyses, when the recording has a reference rotation). Above DISPLAY_MAX_HZ it is shown as the mean of
  consecutive valid samples (decimated for display only; the engine sees every sample,
  the series name says "mean of k samples"). ``aux/<name>`` the same for aux channels
  (with more than AUX_ONE_ROW, ``aux/<name>/y_range``: the range so far rounded out).
- ``dadev/log10_adev_dph`` log10 of the ADEV (deg/h) at every tau, one row per window
  (time = the window's last sample); ``dadev/heatmap`` the latest HEATMAP_WINDOWS windows
  as a colour image (``image``; rows: tau, largest at the top; columns: windows, newest
  on the right) with tau labels, window-end-time labels and a colour scale in deg/h
  (whole decades fixed at the first windows; values beyond take the end colours).
- ``adev_curve/log10/*`` the current window's ADEV curve with its confidence bounds and the
  fitted IEEE-952 model (drawn only over the taus the fit used: ``model_span``), as
  x = log10(tau / s), y = log10(ADEV / (deg/h)) with a labelled decade grid and a legend
  (plot views have no log axes); with --model the model's band (``model_band``: lo,
  median, hi lines, and ``model_band/bars`` one bar per tau).
- ``coef/<name>`` each IEEE-952 coefficient with its interval (series value, lo, hi;
  only windows where it is identifiable) - the "2-D diagram" of the MWD papers;
  ``coef/<name>/upper_limit`` its 95 % upper limit in the windows where it is not;
  ``coef/<name>/y_range`` invisible points at the track's range so far rounded out
  (plots.nice_range), so that the view's y axis shows tick values.
- ``events`` a text log (gaps, CRC errors, reconnects, coefficient jumps), each message
  starting with its recording time in s; ``counters/<name>`` the source's counters.

Several axes (``StreamInfo.axes``): each axis's rate, DADEV, heatmap, ADEV curve (with
its model band) and coefficients go under ``axis/<name>/`` (``axis/x/rate/rate_dph``,
``axis/x/adev_curve/log10/adev_dph``, ``axis/x/coef/N_dpsh``, ...), its events to
``axis/<name>/events`` (the message says the axis); the decade grid and legend of the overlaid ADEV curves stay at
``adev_curve/log10``, aux channels at ``aux/<name>``, whole-stream events at ``events``.
Each axis has one colour (AXIS_COLOURS) in every view: rates, ADEV curves and coefficient
tracks of all axes overlaid, one heatmap per axis side by side (``blueprint`` with ``axes``).
A one-axis stream keeps the paths and layout above.
"""
from __future__ import annotations

import contextlib
import math
import os
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from fogmon import startup, stopping
from fogmon.block import Block, Event
from fogmon.errors import FogmonError
from fogmon.formats.archive import piece_path
from fogmon.outputs import Output, check_outputs, write_failed
from fogmon.sinks.base import COEFFICIENTS, Sink, StreamInfo
from fogmon.sinks.rerun import plots as rp
from fogmon.sinks.rerun.accel import AccelViews
from fogmon.sinks.rerun.blueprint import CURVE, HEATMAP, TIMELINE, Y_RANGE, axis_path, blueprint, heatmap_height
from fogmon.sinks.rerun.columns import (
    _Decimator,
    _Rows,
    _send_bounds,
    _send_curves,
    _send_models,
    _send_scalars,
    _send_texts,
)
from fogmon.sinks.rerun.plots import model_span, model_taus
from fogmon.sinks.rerun.server import _check_listening, start_grpc_server, stop_process_group
from fogmon.sinks.rerun.style import (
    BAND_COLOUR,
    BOUNDS_COLOUR,
    HEATMAP_COLORMAP,
    MEASURED_COLOUR,
    MODEL_COLOUR,
    _styles,
    aux_colour,
)

if TYPE_CHECKING:
    from rerun import RecordingStream


#: Raw rate and aux channels are shown at no more than this many points per second.
DISPLAY_MAX_HZ = 100.0
#: Columns (windows) in the DADEV heatmap image.
HEATMAP_WINDOWS = 256
#: Send what is waiting (raw samples; windows' curves, coefficients, DADEV rows; counters
#: and events) to Rerun at least this often (wall time, s) or every FLUSH_SAMPLES raw
#: samples, each entity's rows in one call. A call costs ~0.2-0.5 ms of CPU whatever its
#: length: once a second keeps a live three-axis KVH's raw traces near 0.3 % of a core and
#: still refreshes the views faster than a person reads them.
FLUSH_WALL_S = 1.0
FLUSH_SAMPLES = 1 << 16
#: At the end, wait at most this long (s) for Rerun to deliver everything.
FLUSH_TIMEOUT_S = 30.0
#: More aux channels than this share two rows of small views (about 60 pixels tall), whose
#: y ranges are rounded out (plots.nice_range) to at most AUX_STEPS steps: two labelled
#: ticks. In one row (about 200 pixels) the data's own range is labelled.
AUX_ONE_ROW, AUX_STEPS = 3, 3
#: Child of ``coef/<name>``: the 95 % upper limit in windows where the coefficient is not identifiable.
UPPER_LIMIT = "upper_limit"
_LEVELS = {"gap": "WARN", "crc_error": "WARN", "seq_gap": "WARN", "disconnect": "ERROR",
           "reconnect": "WARN", "coef_jump": "INFO", "implausible": "WARN", "bad_input": "WARN",
           "platform_motion": "WARN"}


def _adev_decades(rate_dph: np.ndarray, n_taus: int) -> tuple[int, int]:
    """Decades (log10 deg/h) to frame the ADEV curve, guessed from the first samples:
    the ADEV at tau0 is about their standard deviation; longer taus fall at most 0.3
    decade per octave (quantization noise) or rise with rate random walk."""
    sd = float(np.std(rate_dph)) if len(rate_dph) > 1 else 0.0
    top = math.ceil(math.log10(sd * 1.5)) if sd > 0 and math.isfinite(sd) else 2
    return top - max(3, math.ceil(0.3 * n_taus)), top + 1


class _Streams:
    """The Rerun recording streams that get every call: ``live`` (gRPC: --serve, --connect)
    and ``file`` (the current .rrd piece, replaced at each --rotate-s seam)."""

    def __init__(self) -> None:
        self.live: RecordingStream | None = None
        self.file: RecordingStream | None = None

    def all(self) -> list:
        return [r for r in (self.live, self.file) if r is not None]

    def log(self, *args, **kwargs) -> None:
        for r in self.all():
            r.log(*args, **kwargs)

    def send_columns(self, *args, **kwargs) -> None:
        for r in self.all():
            r.send_columns(*args, **kwargs)

    def set_time(self, *args, **kwargs) -> None:
        for r in self.all():
            r.set_time(*args, **kwargs)


@dataclass
class _Heat:
    """One axis's heatmap: log10 ADEV rows of the latest windows, their end times (s), and
    the colour scale (whole decades of log10 ADEV, fixed at the first frames)."""

    rows: list[np.ndarray] = field(default_factory=list)
    t_s: list[float] = field(default_factory=list)
    decades: tuple[int, int] | None = None
    scale_sent: bool = False       # the colour scale is drawn (static) in the current .rrd piece


class RerunSink(Sink):
    """Streams the pipeline into Rerun: ``rrd_path`` (file; with ``rotate`` one file per
    piece, named by fogmon.formats.archive: OUT-0001.rrd, ..., each a complete recording with the
    blueprint, all with one recording id so the viewer joins them), ``connect_url`` (a
    running viewer or server), ``serve`` (start a gRPC server on ``bind:port``), any
    combination; with ``serve_wait`` a server keeps serving after the run until Ctrl-C
    (or SIGTERM, SIGHUP). Problems with the outputs (a folder given as --rrd, an
    unwritable path, a busy port, no viewer at the URL) are one-line errors here, before
    any data; a run that delivers no sample leaves no .rrd behind."""

    def __init__(self, rrd_path: str | None = None, connect_url: str | None = None, serve: bool = False,
                 bind: str = "127.0.0.1", port: int = 9876, serve_wait: bool = True, rotate: bool = False):
        if not (rrd_path or connect_url or serve):
            raise ValueError("RerunSink needs rrd_path, connect_url or serve")
        self.rrd_path, self.connect_url, self.serve = rrd_path, connect_url, serve
        self.bind, self.port, self.serve_wait, self.rotate_files = bind, port, serve_wait, rotate
        self.server: subprocess.Popen | None = None
        self.server_url: str | None = None
        self.rec: _Streams | None = None
        self.pieces: list[str] = []          # .rrd files written (one unless rotate)
        self.error: FogmonError | None = None   # a .rrd that could not be written (removed)
        self._recording_id = str(uuid.uuid4())
        self._piece = 1
        self._last_flush = time.monotonic()
        self._legend_sent = False
        self._band_alpha: float | None = None
        self._rows: dict[str, _Rows] = {}    # entity -> rows waiting for the next flush
        self._y_ranges: dict[str, tuple[float, float]] = {}   # coefficient -> (min, max) drawn so far, all axes
        self._pending_events: list[Event] = []   # before the first sample: entities not known yet
        if connect_url:
            _check_listening(connect_url)
        if rrd_path:
            self._check_rrd()
        if serve:
            self.server, self.server_url = start_grpc_server(bind, port)
            print(f"fogmon: serving Rerun on {self.server_url} (open it with: rerun {self.server_url})",
                  file=sys.stderr)

    def _piece_path(self) -> str:
        assert self.rrd_path is not None, "called with --rrd only"
        return piece_path(self.rrd_path, self._piece) if self.rotate_files else self.rrd_path

    def _check_rrd(self) -> None:
        """Fail before the source is opened, not at the first sample (fogmon.outputs: its
        folder exists, it can be written; nothing is created)."""
        assert self.rrd_path is not None, "called with --rrd only"
        check_outputs([Output("`rrd_path`", self.rrd_path, pieces=self.rotate_files)])

    # -- set-up ---------------------------------------------------------------
    def start(self, info: StreamInfo) -> None:
        self.info = info
        self.step = max(1, int(math.ceil(info.sample_rate_hz / DISPLAY_MAX_HZ)))
        self.dec = _Decimator(self.step)
        self._styles = _styles(info.axes)      # keys: the axis names, "" for a one-axis stream
        self._heat = {a: _Heat() for a in self._styles}
        self.accel = AccelViews(info.accels, info.tau_s) if info.accels else None
        self._accel_legend_sent = False

    def _setup(self, first: Block) -> None:
        """Open the streams and send the blueprint; the first block frames the ADEV view."""
        startup.arrow_without_pandas()
        import rerun as rr

        info = self.info
        tau = info.tau_s
        x_dec = (math.floor(np.log10(tau[0])), math.ceil(np.log10(tau[-1]))) if len(tau) else (-2, 2)
        error_rate = info.analysed != "rate_dph"
        y_decs = []
        for a in self._styles:
            b = first.axis(a) if a else first
            y = b.error_rate_dph if error_rate else b.rate_dph
            y_decs.append(_adev_decades(y[b.valid & np.isfinite(y)], len(tau)))
        for lo, _, hi in info.model_bands.values():      # the --model band is drawn whole
            with np.errstate(divide="ignore", invalid="ignore"):
                band = np.log10(np.r_[np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)])
            if np.isfinite(band).any():
                y_decs.append((math.floor(np.nanmin(band[np.isfinite(band)])),
                               math.ceil(np.nanmax(band[np.isfinite(band)]))))
        self._decades = (x_dec, (min(d[0] for d in y_decs), max(d[1] for d in y_decs)))
        if self.accel is not None:
            self.accel.frame_from(first.aux)
        self._blueprint = blueprint(info.aux_names, self._decades, error_rate, info.axes,
                                    self.accel.tab() if self.accel is not None else None)
        self.rec = _Streams()
        live = [rr.GrpcSink(url) for url in (self.server_url, self.connect_url) if url]
        if live:
            self.rec.live = rr.RecordingStream("fogmon", recording_id=self._recording_id)
            self.rec.live.set_log_time_enabled(False)
            self.rec.live.set_sinks(*live, default_blueprint=self._blueprint)
        if self.rrd_path:
            self._open_piece()
        self._log_static(self.rec)
        pending, self._pending_events = self._pending_events, []
        self.events(pending)

    def _open_piece(self) -> None:
        import rerun as rr

        path = self._piece_path()
        assert self.rec is not None, "the streams open with the first block"
        self.rec.file = rr.RecordingStream("fogmon", recording_id=self._recording_id)
        self.rec.file.set_log_time_enabled(False)
        self.rec.file.save(path, default_blueprint=self._blueprint)
        self.pieces.append(path)

    def _log_static(self, rec) -> None:
        """Series names and styles, the session text, the ADEV view's scale and grid."""
        import rerun as rr

        info = self.info
        tau = info.tau_s
        for a, st in self._styles.items():
            what = "rate_dph" if self.step == 1 else f"rate_dph (mean of {self.step} samples, display only)"
            rec.log(axis_path(a, "rate/rate_dph"), rr.SeriesLines(names=[st.label + what], widths=[1.0],
                                                                  colors=st.rate and [st.rate]), static=True)
            if info.analysed != "rate_dph":
                rec.log(axis_path(a, "rate/error_dph"),
                        rr.SeriesLines(names=[f"{st.label}{info.analysed} (analysed)"], colors=st.rate and [st.rate]),
                        static=True)
            rec.log(axis_path(a, "dadev/log10_adev_dph"), rr.SeriesLines(names=[f"tau={t:.4g} s" for t in tau]),
                    static=True)
            for n, u in COEFFICIENTS.items():
                c = st.coef[n]
                rec.log(axis_path(a, f"coef/{n}"), rr.SeriesLines(
                    names=[f"{st.label}{n} ({u})", f"{st.label}lo", f"{st.label}hi"], colors=[c, c, c],
                    widths=[2.0, 0.7, 0.7]), static=True)
                rec.log(axis_path(a, f"coef/{n}/{UPPER_LIMIT}"), rr.SeriesPoints(
                    names=[f"{st.label}upper limit (not identifiable)"], colors=[c], markers=["down"],
                    marker_sizes=[3.0]), static=True)
                rec.log(axis_path(a, f"coef/{n}/{Y_RANGE}"), rr.SeriesPoints(
                    names=["y axis range (rounded out), bottom", "y axis range (rounded out), top"],
                    colors=[(0, 0, 0, 0)] * 2, marker_sizes=[0.0, 0.0]), static=True)
        for k, name in enumerate(info.aux_names):
            label = name if self.step == 1 else f"{name} (mean of {self.step} samples)"
            rec.log(f"aux/{name}", rr.SeriesLines(names=[label], colors=[aux_colour(k)]), static=True)
            if len(info.aux_names) > AUX_ONE_ROW:
                rec.log(f"aux/{name}/{Y_RANGE}", rr.SeriesPoints(
                    names=["y axis range (rounded out), bottom", "y axis range (rounded out), top"],
                    colors=[(0, 0, 0, 0)] * 2, marker_sizes=[0.0, 0.0]), static=True)
        axes = f"axes: {', '.join(info.axes)}\n" if info.axes else ""
        rec.log("session", rr.TextDocument(
            f"source: {info.source_name}\n{axes}analysed: {info.analysed} (deg/h)\n"
            f"sample rate: {info.sample_rate_hz:g} Hz\nwindow: {info.window_s:g} s, hop: {info.hop_s:g} s\n"
            f"taus: {len(tau)} from {tau[0]:.4g} to {tau[-1]:.4g} s" if len(tau) else
            f"source: {info.source_name}"), static=True)
        if self.accel is not None:
            self.accel.log_static(rec)
        x_dec, y_dec = self._decades
        rec.log(CURVE, rp.loglog_transform(), static=True)
        rp.log_decade_grid(rec, CURVE, x_dec, y_dec, "s", "deg/h")
        self._band_alpha = info.model_alpha
        for a, st in self._styles.items():
            if a:
                rec.log(axis_path(a, CURVE), rp.loglog_transform(), static=True)
            band = info.model_bands.get(a)
            if band is not None and len(tau):
                lx = np.log10(tau)
                lb = [np.log10(np.asarray(b, dtype=np.float64)) for b in band]
                lines = [np.column_stack([lx, y]) for y in lb]
                radii = np.array([rr.Radius.ui_points(w) for w in (1.0, 0.5, 1.0)], dtype=np.float32)
                rec.log(f"{axis_path(a, CURVE)}/model_band", rr.LineStrips2D(lines, colors=[st.band], radii=radii),
                        static=True)
                rp.log_band_bars(rec, f"{axis_path(a, CURVE)}/model_band/bars", lx, lb[0], lb[2], st.band)

    # -- data -----------------------------------------------------------------
    def block(self, block: Block) -> None:
        first = self.rec is None
        if first:
            self._setup(block)
        chans = {}
        for a in self._styles:
            b = block.axis(a) if a else block
            chans[axis_path(a, "rate/rate_dph")] = np.where(b.valid, b.rate_dph, np.nan)
            if self.info.analysed != "rate_dph":
                chans[axis_path(a, "rate/error_dph")] = np.where(b.valid, b.error_rate_dph, np.nan)
        chans.update({f"aux/{k}": v for k, v in block.aux.items()})
        self.dec.push(block.t_s, chans)
        if first or time.monotonic() - self._last_flush > FLUSH_WALL_S or self.dec.pending() >= FLUSH_SAMPLES:
            self._flush()     # the first samples at once: a viewer shows them while the kernels load

    def _flush(self, final: bool = False) -> None:
        """Send the raw samples' completed display bins (all with ``final``) and every
        entity's waiting rows."""
        import rerun as rr

        self._last_flush = time.monotonic()
        assert self.rec is not None, "the streams open with the first block"
        t, vals = self.dec.take(final)
        for ent, v in vals.items():
            ok = np.isfinite(v)
            if ok.any():
                self.rec.send_columns(ent, indexes=[rr.TimeColumn(TIMELINE, duration=t[ok])],
                                      columns=rr.Scalars.columns(scalars=v[ok]))
                if ent.startswith("aux/") and len(self.info.aux_names) > AUX_ONE_ROW:
                    self._queue_aux_range(ent, float(t[ok][-1]), v[ok])
        for ent, rows in self._rows.items():
            if rows.t_s:
                rows.send(self.rec, ent, np.array(rows.t_s, dtype=np.float64), rows.values)
                rows.t_s, rows.values = [], []

    def _queue(self, entity: str, send: Callable[[Any, str, np.ndarray, list], None], t_s, values) -> None:
        """Rows of ``entity`` (times in s, values) for the next flush, sent by ``send``."""
        rows = self._rows.get(entity)
        if rows is None:
            rows = self._rows[entity] = _Rows(send)
        rows.t_s.extend(float(t) for t in t_s)
        rows.values.extend(values)

    def frames(self, dadev, fit, t_end_s: np.ndarray, axis: str = "") -> None:
        assert self.rec is not None, "the streams open with the first block"
        if axis not in self._styles:
            raise ValueError(f"RerunSink.frames: axis {axis!r} is not one of the stream's axes {self.info.axes}")
        rec = self.rec
        with np.errstate(divide="ignore", invalid="ignore"):
            log_adev = np.log10(np.asarray(dadev.adev_dph, dtype=np.float64))
        self._queue(axis_path(axis, "dadev/log10_adev_dph"), _send_scalars, t_end_s, list(log_adev))
        for name in COEFFICIENTS:
            c = getattr(fit, name)
            v, lo, hi = (np.asarray(getattr(c, a), dtype=np.float64) for a in ("value", "lo", "hi"))
            ident = np.asarray(c.identifiable, dtype=bool)
            ok = ident & np.isfinite(v) & np.isfinite(lo) & np.isfinite(hi)
            self._queue(axis_path(axis, f"coef/{name}"), _send_scalars, t_end_s[ok],
                        list(np.column_stack([v[ok], lo[ok], hi[ok]])))
            up = ~ident & np.isfinite(hi)     # not identifiable: hi is the 95 % upper limit
            self._queue(axis_path(axis, f"coef/{name}/{UPPER_LIMIT}"), _send_scalars, t_end_s[up], list(hi[up]))
            drawn = np.where(ok[:, None], np.column_stack([v, lo, hi]), np.where(up, hi, np.nan)[:, None])
            self._queue_y_range(axis, name, t_end_s, drawn)
        if not self._legend_sent:
            self._log_legend(dadev.confidence)
        tau = np.asarray(dadev.tau_s, dtype=np.float64)
        rec.set_time(TIMELINE, duration=float(t_end_s[-1]))
        self._log_heatmap(axis, log_adev, t_end_s, tau)
        lx = np.log10(tau)
        misfit = np.asarray(fit.misfit, dtype=bool).reshape(np.shape(dadev.adev_dph))
        dense = model_taus(tau)
        model = np.asarray(fit.model_adev_dph(dense), dtype=np.float64).reshape(len(t_end_s), len(dense))
        for i in range(len(t_end_s)):
            self._queue_curve(axis, float(t_end_s[i]), lx, dadev.adev_dph[i], dadev.lo_dph[i], dadev.hi_dph[i], tau,
                              misfit[i], dense, model[i])

    def accel_frames(self, dadev, fit, t_end_s: np.ndarray, accel: str) -> None:
        assert self.rec is not None and self.accel is not None, "the streams open with the first block"
        self.accel.frames(self._queue, dadev, fit, t_end_s, accel)
        if not self._accel_legend_sent:
            self.accel.log_legend(self.rec, dadev.confidence)
            self._accel_legend_sent = True

    def _queue_y_range(self, axis: str, name: str, t_end_s: np.ndarray, drawn: np.ndarray) -> None:
        """The rounded-out range (plots.nice_range) of everything coefficient ``name``'s
        tracks (of every axis: they share a view) drew up to each window of ``axis``
        (``drawn``: windows x values, NaN: not drawn), as ``coef/<name>/y_range`` points at
        the windows' ends: the view fits its y axis to them."""
        w_lo, w_hi = np.fmin.reduce(drawn, axis=1), np.fmax.reduce(drawn, axis=1)
        prev = self._y_ranges.get(name, (np.nan, np.nan))
        run_lo = np.fmin.accumulate(np.r_[prev[0], w_lo])[1:]
        run_hi = np.fmax.accumulate(np.r_[prev[1], w_hi])[1:]
        if len(run_lo):
            self._y_ranges[name] = (float(run_lo[-1]), float(run_hi[-1]))
        ok = np.isfinite(run_lo) & np.isfinite(run_hi)
        self._queue(axis_path(axis, f"coef/{name}/{Y_RANGE}"), _send_scalars, t_end_s[ok],
                    [np.array(rp.nice_range(a, b)) for a, b in zip(run_lo[ok], run_hi[ok], strict=True)])

    def _queue_aux_range(self, entity: str, t_s: float, values: np.ndarray) -> None:
        """An aux channel's range so far, rounded out (plots.nice_range, AUX_STEPS), as
        ``aux/<name>/y_range`` points at ``t_s`` (s)."""
        lo, hi = self._y_ranges.get(entity, (math.inf, -math.inf))
        lo, hi = min(lo, float(values.min())), max(hi, float(values.max()))
        self._y_ranges[entity] = (lo, hi)
        self._queue(f"{entity}/{Y_RANGE}", _send_scalars, [t_s], [np.array(rp.nice_range(lo, hi, AUX_STEPS))])

    def _log_legend(self, confidence: float) -> None:
        """The ADEV-curve view's legend (static; the bounds' confidence is known from the
        first frames): what each line is; with several axes, each axis's colour and the
        shades of its bounds, model and band."""
        alpha = self._band_alpha
        band = [] if alpha is None else ["--model band" + ("" if self.info.axes else
                                                           f", family-wise {alpha:g}/window")]
        if not self.info.axes:
            items = [("measured ADEV, current window", MEASURED_COLOUR),
                     (f"{100 * confidence:.1f} % confidence bounds", BOUNDS_COLOUR),
                     ("IEEE-952 model (fitted taus)", MODEL_COLOUR),
                     *((b, BAND_COLOUR) for b in band)]
        else:
            items = [*((f"axis {a}: measured ADEV", st.measured) for a, st in self._styles.items()),
                     (f"darker: {100 * confidence:.1f} % bounds", rp.LABEL_COLOUR),    # shades of each axis's colour
                     ("lighter: IEEE-952 model", rp.LABEL_COLOUR),
                     *((f"greyed: {b}", rp.LABEL_COLOUR) for b in band)]
        rp.log_loglog_legend(self.rec, f"{CURVE}/legend", items, *self._decades)
        self._legend_sent = True

    def _log_heatmap(self, axis: str, log_adev: np.ndarray, t_end_s: np.ndarray, tau: np.ndarray) -> None:
        """Axis ``axis``'s latest HEATMAP_WINDOWS windows as a colour image (rows: tau, largest on top;
        columns: windows, newest right) with window-end-time labels and a colour scale in
        deg/h fixed at the first frames' whole decades."""
        h = self._heat[axis]
        h.rows += [row.astype(np.float32) for row in log_adev]
        h.t_s += [float(t) for t in t_end_s]
        del h.rows[:-HEATMAP_WINDOWS], h.t_s[:-HEATMAP_WINDOWS]
        if h.decades is None:
            fin = log_adev[np.isfinite(log_adev)]
            lo, hi = (math.floor(fin.min()), math.ceil(fin.max())) if fin.size else (-1, 1)
            h.decades = (lo, max(hi, lo + 1))
        lo, hi = h.decades
        heat = np.stack(h.rows, axis=1)[::-1]  # rows: largest tau on top
        n_cols = heat.shape[1]
        rows = rp.decade_rows(tau)
        n_labels = 5 if len(self._styles) == 1 else 3     # several axes: narrow heatmaps side by side
        cols = np.unique(np.linspace(0, n_cols - 1, min(n_cols, n_labels)).round().astype(int))
        entity, height = axis_path(axis, HEATMAP), heatmap_height(self.info.axes)
        if not h.scale_sent:     # fixed from the first frames on: drawn once, not every window
            decades = np.arange(lo, hi + 1)
            rp.log_heatmap_scale(self.rec, entity, lo, hi, HEATMAP_COLORMAP,
                                 (decades, [f"{10.0**d:g} deg/h" for d in decades]), static=True, height=height)
            h.scale_sent = True
        rp.log_heatmap(self.rec, entity, heat, lo, hi, HEATMAP_COLORMAP,
                       ([len(tau) - 1 - i for i in rows], [f"{tau[i]:.3g} s" for i in rows]),
                       (cols, [_time_label(h.t_s[c]) for c in cols]), None, height=height)

    def _queue_curve(self, axis, t_s, lx, adev, lo, hi, tau, misfit, dense, model) -> None:
        """The ADEV curve and bounds of axis ``axis`` in the window ending at ``t_s`` (s),
        and its model (``model`` at taus ``dense``) over the taus the fit used, for the
        next flush."""
        with np.errstate(divide="ignore", invalid="ignore"):
            ly, llo, lhi = (np.log10(np.asarray(a, dtype=np.float64)) for a in (adev, lo, hi))
        ok = np.isfinite(ly)
        if not ok.any():
            return
        curve, st = axis_path(axis, CURVE), self._styles[axis]
        self._queue(f"{curve}/adev_dph", partial(_send_curves, colour=st.measured), [t_s],
                    [np.column_stack([lx[ok], ly[ok]])])
        b = ok & np.isfinite(llo) & np.isfinite(lhi)
        self._queue(f"{curve}/bounds", partial(_send_bounds, colour=st.bounds), [t_s],
                    [(np.column_stack([lx[b], llo[b]]), np.column_stack([lx[b], lhi[b]]))])
        span = model_span(tau, adev, misfit)
        with np.errstate(divide="ignore", invalid="ignore"):
            lm = np.log10(model)
        m_ok = (np.isfinite(lm) & (dense >= span[0]) & (dense <= span[1])) if span is not None else np.zeros(0, bool)
        line = np.column_stack([np.log10(dense[m_ok]), lm[m_ok]]) if m_ok.sum() >= 2 else None
        self._queue(f"{curve}/model_ieee952", partial(_send_models, colour=st.model), [t_s], [line])

    def events(self, events: Sequence[Event]) -> None:
        """Events for the next flush: an axis's under it (several axes), the whole
        stream's at ``events``."""
        if self.rec is None:   # before the first sample (e.g. a source reconnecting)
            self._pending_events.extend(events)
            return
        for e in events:
            own = e.axis in self.info.axes
            self._queue(axis_path(e.axis, "events") if own else "events", _send_texts,
                        [e.t_s], [(event_text(e, own), _LEVELS.get(e.kind, "INFO"))])

    def source_counters(self, t_s: float, counters: dict[str, int]) -> None:
        for k, v in counters.items():
            self._queue(f"counters/{k}", _send_scalars, [t_s], [float(v)])

    def rotate(self, piece: int, t_s: float) -> None:
        """Close the current .rrd piece (complete, with its footer) and start the next;
        the live stream goes on."""
        if not (self.rotate_files and self.rec is not None and self.rec.file is not None):
            return
        self._flush(final=True)
        if not self._close_file():
            return
        self._piece = piece
        self._open_piece()
        self._log_static(self.rec.file)
        self._legend_sent = self._accel_legend_sent = False
        for h in self._heat.values():
            h.scale_sent = False

    def finish(self, summary) -> None:
        """Flush everything, complete the .rrd, keep serving a replay's viewers until
        Ctrl-C, then stop the server; without any sample only clean up."""
        if self.rec is not None:
            self._flush(final=True)
            if self.rec.file is not None:
                self._close_file()
            if self.pieces:
                summary.outputs.append(self.pieces[0] if len(self.pieces) == 1 else
                                       f"{self.pieces[0]} .. {self.pieces[-1]} ({len(self.pieces)} pieces)")
            if self.rec.live is not None:
                _rerun_call(self.rec.live.flush, timeout_sec=FLUSH_TIMEOUT_S)
                if self.server is not None and self.serve_wait and not summary.interrupted:
                    self._serve_until_stopped()
                _rerun_call(self.rec.live.disconnect)
        if self.server is not None:
            stop_process_group(self.server)

    def _close_file(self) -> bool:
        """Complete the current .rrd piece; False when it could not be written (a full
        disk: Rerun's file writer stopped): then the piece is removed with a warning,
        ``error`` says why (fogmon.outputs.write_failed) and no more is written to files."""
        assert self.rec is not None and self.rec.file is not None, "a .rrd piece is open"
        path = self.pieces[-1]
        try:
            self.rec.file.flush(timeout_sec=FLUSH_TIMEOUT_S)
            ok = True
        except RuntimeError as e:
            ok = False
            why = str(e).splitlines()[0]
        _rerun_call(self.rec.file.disconnect)
        self.rec.file = None
        if not ok:
            with contextlib.suppress(OSError):
                os.remove(path)
            self.pieces.remove(path)
            self.error = write_failed("`rrd_path`", path, f"Rerun: {why}")
            print(f"fogmon: warning: {path}: Rerun could not complete it ({why}); removed", file=sys.stderr)
        return ok

    def _serve_until_stopped(self) -> None:
        print(f"fogmon: done; still serving {self.server_url} for viewers - press Ctrl-C to stop", file=sys.stderr)
        assert self.server is not None, "called with --serve only"
        try:
            while self.server.poll() is None and not stopping.stop_requested():
                time.sleep(0.5)
        except KeyboardInterrupt:   # Ctrl-C where fogmon's stop handlers are not installed
            pass


def _time_label(t_s: float) -> str:
    """A heatmap column's label: its window's end time, whole seconds from 100 s on."""
    return f"{t_s:.0f} s" if abs(t_s) >= 100 else f"{t_s:.4g} s"


def event_text(e: Event, of_axis: bool = False) -> str:
    """An event's line in the event log: its recording time (s), with ``of_axis`` its
    axis, its kind (left out where the message starts with it in words) and message."""
    kind = "" if e.message.lower().startswith(e.kind.replace("_", " ")) else f"{e.kind}: "
    return f"{e.t_s:.2f} s  {f'axis {e.axis}: ' if of_axis else ''}{kind}{e.message}"


def _rerun_call(fn, **kwargs) -> None:
    """A Rerun call whose failure (a viewer that went away) is a warning: the file is
    complete regardless."""
    try:
        fn(**kwargs)
    except RuntimeError as e:
        print(f"fogmon: warning: Rerun: {str(e).splitlines()[0]}", file=sys.stderr)
