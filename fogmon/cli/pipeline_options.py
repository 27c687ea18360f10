"""Command-line options of the streaming pipeline (`fogmon replay`, `fogmon monitor`):
engine, outputs, pacing; and what they build: a PipelineConfig and the sinks. The only
place that reads these options from an argparse namespace."""
from __future__ import annotations

import argparse
import warnings
from dataclasses import replace

import numpy as np

from fogmon.block import parse_axes
from fogmon.cli.output_options import rotated
from fogmon.cli.values import number, positive
from fogmon.davar.taus import MAX_PER_DECADE, check_per_decade
from fogmon.errors import FogmonError, FogmonWarning
from fogmon.methods.live import LiveMethods
from fogmon.methods.live_thermal import axis_thermal_effect, thermal_effect
from fogmon.pipeline import LIVE_WINDOW_SAMPLES, MAX_WINDOW_SAMPLES, MIN_WINDOW_SAMPLES, PipelineConfig
from fogmon.sim.model import SensorModel, load_model
from fogmon.sinks.base import Sink

#: default recording time (s) per archive piece of `fogmon monitor` (--rotate-s)
ARCHIVE_ROTATE_S = 3600.0


def add_pipeline_arguments(parser: argparse.ArgumentParser, replay: bool = True) -> None:
    """Options of `fogmon replay` and `fogmon monitor` (``replay=False``: no --realtime):
    engine, sinks, pacing."""
    _add_davar_arguments(parser)
    _add_method_arguments(parser)
    _add_output_arguments(parser, replay)
    _add_pacing_arguments(parser, replay)


def _add_davar_arguments(parser: argparse.ArgumentParser) -> None:
    """Window, hop, taus and what the engine analyses."""
    g = parser.add_argument_group("dynamic Allan deviation (DAVAR)")
    g.add_argument("--window-s", type=positive, metavar="W",
                   help="window length in s. Default: replay: a quarter of the recording (of its first "
                        "--duration-s s) rounded down to a power of two of samples, within "
                        f"{MIN_WINDOW_SAMPLES}..{MAX_WINDOW_SAMPLES} samples; live: {LIVE_WINDOW_SAMPLES} samples "
                        "(65.5 s at 1 kHz, 655.4 s at 100 Hz), or that rule applied to --duration-s when it "
                        "gives a shorter window")
    g.add_argument("--hop-s", type=positive, metavar="H",
                   help="a new ADEV + noise fit every H s of recording time, at most the window "
                        "(default: window/8)")
    g.add_argument("--raw-rate", action="store_true",
                   help="analyse rate_dph as recorded even when the recording has rot_dps; by default "
                        "DAVAR and the fits see the gyro's error rate_dph - 3600 x rot_dps (deg/h) "
                        "against the reference rotation")
    g.add_argument("--keep-motion", action="store_true",
                   help="analyse platform motion too: by default stretches where the rate moves far beyond "
                        "the sensor's noise with no rot_dps to say why (a turntable, a vehicle, a person) "
                        "are kept out of DAVAR and the fits, with platform_motion events (docs/motion.md)")
    g.add_argument("--taus", default=PipelineConfig.taus, type=parse_taus, metavar="T",
                   help="averaging times: octave (default), decade, all, an integer N = "
                        f"1..{MAX_PER_DECADE} (N log-spaced per decade), or tau values in s written with a "
                        "decimal point or comma-separated (1000.0 = one tau of 1000 s; 0.1,1,10). Only "
                        "one sample <= tau <= window/4 can be computed: other values are left out with a "
                        "warning")


def _add_method_arguments(parser: argparse.ArgumentParser) -> None:
    """The live methods: model check, thermal calibration, outlier rejection, denoising."""
    m = parser.add_argument_group("live methods and model check (docs/monitor.md)")
    m.add_argument("--model", metavar="MODEL.toml",
                   help="check every window against the model's DADEV band (its IEEE-952 noise and aux-free noise "
                        "effects, docs/modelcheck.md): a model_band event, with the taus, the ratio to the model, "
                        "the tau shape and the aux channel that co-varies, when the gyro leaves the band and when "
                        "it is back; the band is simulated once and cached (~/.cache/fogmon)")
    m.add_argument("--model-alpha", type=number(0, 0.5, above=True), default=PipelineConfig.model_alpha,
                   metavar="A", help="family-wise false-alarm probability per window of the model check, "
                                     f"0 < A <= 0.5 (default {PipelineConfig.model_alpha:g})")
    m.add_argument("--thermal-cal", metavar="CAL.toml",
                   help="subtract the thermal drift K0(T) + K1 dT/dt + K2 d2T/dt2 calibrated by `fogmon thermal "
                        "--out-model CAL.toml` sample by sample (causal filters; needs temp_c); DAVAR and the fits "
                        "see the corrected rate, rate_corrected_dph and thermal_drift_dph (deg/h) are archived "
                        "and drawn beside the raw rate; --raw-rate analyses the raw rate")
    m.add_argument("--reject-outliers", nargs="?", const=7.0, type=number(2, 100, above=True), metavar="K",
                   help="reject samples beyond K sigmas of one sample from the level the samples before them "
                        "predict (a robust, causal Pauta criterion; default K = 7: 5.8e-10 of Gaussian samples); "
                        "rejected samples are invalid for DAVAR, kept in the archive, counted "
                        "(outliers_rejected) and reported as outlier events")
    m.add_argument("--denoise", choices=("kalman",),
                   help="kalman: a steady-state Kalman estimate of the rate (N and K from the [noise] of --model "
                        "or --thermal-cal; per axis from the [noise.<axis>] tables of a --model of several axes) as "
                        "the channel rate_kalman_dph (deg/h; rate_kalman_dph_<axis> per axis), archived and drawn "
                        "beside raw")


def _add_output_arguments(parser: argparse.ArgumentParser, replay: bool) -> None:
    """Rerun outputs, file rotation and the console."""
    o = parser.add_argument_group("output (Rerun)")
    o.add_argument("--rrd", metavar="OUT.rrd", help="write a Rerun recording file (headless); "
                   "open it with `rerun OUT.rrd`")
    o.add_argument("--connect", metavar="URL", nargs="?", const="rerun+http://127.0.0.1:9876/proxy",
                   help="stream to a running Rerun viewer (default URL rerun+http://127.0.0.1:9876/proxy; "
                        "start one with `rerun`)")
    o.add_argument("--serve", action="store_true",
                   help="host a Rerun gRPC server that viewers connect to (`rerun URL` as printed); "
                        "keeps serving after a replay until Ctrl-C")
    o.add_argument("--bind", default="127.0.0.1", metavar="ADDR",
                   help="address --serve listens on (default 127.0.0.1, this machine only; 0.0.0.0 for all)")
    o.add_argument("--port", type=number(1, 65535, integer=True), default=9876,
                   help="port --serve listens on, 1..65535 (default 9876)")
    o.add_argument("--rotate-s", type=_rotate_s, metavar="S", default=None,
                   help=("write the .rrd as pieces OUT-0001.rrd, OUT-0002.rrd, ... of S s of recording time "
                         "each (default: one file, OUT.rrd itself)" if replay else
                         f"start new archive files every S s of recording time: samples-NNNN.csv and the raw "
                         f"capture pieces (default {ARCHIVE_ROTATE_S:g} = hourly; 0 = one piece); given, it also "
                         f"cuts the .rrd into OUT-0001.rrd, ... (by default --rrd OUT.rrd writes OUT.rrd itself)"))
    if not replay:
        parser.set_defaults(archive_rotate_s=ARCHIVE_ROTATE_S)
    o.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    o.add_argument("--quiet", action="store_true", help="no console summary at the end")


def _add_pacing_arguments(parser: argparse.ArgumentParser, replay: bool) -> None:
    """--duration-s and, for a replay, --realtime."""
    p = parser.add_argument_group("pacing")
    if "--duration-s" not in parser._option_string_actions:  # the source options may define it
        p.add_argument("--duration-s", type=positive, metavar="S",
                       help="stop after S s of recording time")
    if replay and "--realtime" not in parser._option_string_actions:
        p.add_argument("--realtime", nargs="?", const=1.0, type=positive, metavar="X",
                       help="pace a replay at X times real time (default X = 1 when given; "
                            "without --realtime a replay runs as fast as it can)")
    parser.set_defaults(realtime=None)  # a live run is never paced


def _rotate_s(text: str) -> float:
    """``--rotate-s``: S > 0, or 0 for no rotation."""
    try:
        if float(text) == 0:
            return 0.0
    except ValueError:
        pass
    return positive(text)


def parse_taus(text: str):
    """``--taus`` value -> what ``tau_grid`` takes: a grid name, an int per decade
    (1..MAX_PER_DECADE), or a tau_s array (values with a decimal point or comma-separated)."""
    s = text.strip().lower()
    if s in ("octave", "decade", "all"):
        return s
    if s.isdigit():
        try:
            return check_per_decade(int(s))
        except FogmonError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    try:
        tau_s = np.array([float(x) for x in s.split(",")], dtype=np.float64)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected octave, decade, all, an integer per decade or tau values in s, got {text!r}") from None
    if not np.all(np.isfinite(tau_s) & (tau_s > 0)):
        raise argparse.ArgumentTypeError(f"tau values must be finite and > 0 s, got {text!r}")
    return tau_s


def pipeline_config(args: argparse.Namespace) -> PipelineConfig:
    """The PipelineConfig of parsed pipeline options (``add_pipeline_arguments``); the
    progress bar only on a terminal and when not paced at or below real time; with
    ``--axis NAME`` a model of several axes is that axis's model."""
    import sys

    realtime = args.realtime
    model = load_model(args.model) if args.model else None
    axis = getattr(args, "axis", None)
    if model is not None and model.axes and axis:   # --axis picked one axis: check it against that axis's model
        try:
            model = model.for_axis(axis)
        except FogmonError as e:
            raise FogmonError(f"--model {args.model}: {e.message}") from None
    cal = load_model(args.thermal_cal) if args.thermal_cal else None
    methods = _live_methods(args, model, cal)
    return PipelineConfig(window_s=args.window_s, hop_s=args.hop_s, taus=args.taus, raw_rate=args.raw_rate,
                          keep_motion=args.keep_motion, duration_s=args.duration_s, realtime=realtime,
                          rotate_s=_pieces_s(args),
                          progress=not args.no_progress and sys.stderr.isatty() and (realtime is None or realtime > 1),
                          methods=methods, axis_methods=_axis_methods(args, model, cal, methods),
                          model=model, model_alpha=args.model_alpha)


def _pieces_s(args: argparse.Namespace) -> float | None:
    """Recording time (s) per output piece: --rotate-s, else the monitor's archive default
    (replay: none); None for one piece."""
    rotate_s = args.rotate_s if args.rotate_s is not None else getattr(args, "archive_rotate_s", None)
    return rotate_s or None


def _live_methods(args: argparse.Namespace, model: SensorModel | None, cal: SensorModel | None) -> LiveMethods:
    """The live methods asked for (of a one-axis stream; a stream of several axes takes
    ``_axis_methods`` where they differ); FogmonError naming the option when a file lacks
    what it needs."""
    thermal = None
    if cal is not None and args.raw_rate:
        warnings.warn(f"--thermal-cal {args.thermal_cal}: not applied, --raw-rate analyses the rate as recorded",
                      FogmonWarning, stacklevel=2)
    elif cal is not None:
        one = _one_axis(args)
        if not _cal_axes(cal):
            thermal = thermal_effect(cal, args.thermal_cal)
        elif one:                         # a calibration per axis, one axis picked: that axis's
            thermal = axis_thermal_effect(cal, args.thermal_cal, one)
    kalman = None
    if args.denoise == "kalman":
        src = next(((m, f) for m, f in ((model, args.model), (cal, args.thermal_cal)) if m is not None), None)
        if src is None:
            raise FogmonError("--denoise kalman needs N_dpsh > 0 and K_dphsh > 0 from the [noise] of --model or "
                              "--thermal-cal")
        kalman = _kalman_n_k(src[0].noise, src[1])
    return LiveMethods(thermal, args.reject_outliers, kalman)


def _one_axis(args: argparse.Namespace) -> str | None:
    """The axis ``--axis`` picks when it picks exactly one, else None."""
    axis = getattr(args, "axis", None)
    names = parse_axes(axis) if axis else ()
    return names[0] if len(names) == 1 else None


def _cal_axes(cal: SensorModel) -> list[str]:
    """The axes a thermal calibration names in its thermal_drift effects (what `fogmon
    thermal --out-model` writes for a recording of several axes); empty for a one-axis file."""
    return sorted({a for e in cal.effects if e.kind == "thermal_drift" for a in e.axes})


def _kalman_n_k(noise, where: str) -> tuple[float, float]:
    """(N deg/sqrt(h), K deg/h/sqrt(h)) of ``noise`` for --denoise kalman; FogmonError
    naming ``where`` unless both are > 0."""
    if not (noise.N_dpsh > 0 and noise.K_dphsh > 0):
        raise FogmonError(f"--denoise kalman needs N_dpsh > 0 and K_dphsh > 0 from the [noise] of --model or "
                          f"--thermal-cal ({where} has N_dpsh {noise.N_dpsh:g}, K_dphsh {noise.K_dphsh:g})")
    return noise.N_dpsh, noise.K_dphsh


def _axis_methods(args: argparse.Namespace, model: SensorModel | None, cal: SensorModel | None,
                  methods: LiveMethods) -> dict[str, LiveMethods]:
    """Each axis's live methods where they differ from ``methods``: the Kalman channel's
    own N and K from a --model of several axes (its [noise.<axis>]), the thermal
    correction from a --thermal-cal with one thermal_drift effect per axis; empty when
    every axis uses ``methods``."""
    out: dict[str, LiveMethods] = {}
    if methods.kalman_n_k is not None and model is not None and model.axes:
        out = {a: replace(methods, kalman_n_k=_kalman_n_k(model.for_axis(a).noise, f"{args.model} [noise.{a}]"))
               for a in model.axes}
    if cal is not None and not args.raw_rate and not _one_axis(args):
        for a in _cal_axes(cal):
            out[a] = replace(out.get(a, methods), thermal=axis_thermal_effect(cal, args.thermal_cal, a))
    return out


def build_sinks(args: argparse.Namespace) -> list[Sink]:
    """The sinks the command line asks for: Rerun (file and/or live) and the console
    (naming parameters as the command's flags)."""
    from fogmon.cli import command_flags
    from fogmon.sinks.console import ConsoleSink

    out: list[Sink] = []
    if args.rrd or args.connect or args.serve:
        from fogmon.sinks.rerun.sink import RerunSink
        out.append(RerunSink(rrd_path=args.rrd, connect_url=args.connect, serve=args.serve, bind=args.bind,
                             port=args.port, rotate=rotated(args)))
    out.append(ConsoleSink(quiet=args.quiet, flags=command_flags(args.command) if "command" in args else None))
    return out


def output_errors(sinks) -> list[FogmonError]:
    """The write errors the sinks met (a full disk under the .rrd or the archive), each
    one line naming the file and the free space."""
    return [e for s in sinks if (e := getattr(s, "error", None)) is not None]
