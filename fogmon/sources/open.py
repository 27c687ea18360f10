"""Command-line options for every source, and opening a live or replayed source from
them (CONTRACT section 3). Used by ``fogmon monitor`` and ``fogmon replay``."""
from __future__ import annotations

import argparse
import os

from fogmon.cli.values import number, positive
from fogmon.errors import FogmonError
from fogmon.sources import plausibility as pl
from fogmon.sources.codecs import DEFAULTS, PROTOCOLS, make_codec

CAN_LOG_SUFFIXES = (".asc", ".blf", ".trc", ".log", ".mf4")
#: The highest --rate-hz accepted (Hz): beyond any gyro's output rate (FOGs stop near 10 kHz).
MAX_RATE_HZ = 1e6


def add_source_arguments(parser: argparse.ArgumentParser, mode: str = "both") -> None:
    """Add the source options. ``mode`` 'live' (monitor), 'replay' or 'both': live adds
    ``--serial``/``--can`` and the port/bus options; replay adds ``--tolerate-bad-rows``;
    decoder options (``--protocol``, ``--dbc``...) go to both. Pacing (``--realtime``) and
    ``--duration-s`` belong to the pipeline (fogmon.pipeline)."""
    live, replay = mode in ("live", "both"), mode in ("replay", "both")
    g = parser.add_argument_group("serial gyro" if live else "raw serial capture decoding")
    if live:
        g.add_argument("--serial", metavar="PORT", help="serial port of the gyro (/dev/ttyUSB0, COM3, or a "
                       "pyserial URL such as loop:// or socket://HOST:PORT); reopened with backoff if it disappears")
        g.add_argument("--baud", type=number(1, 50_000_000, integer=True), metavar="B", help="baud rate, "
                       "1..50,000,000 (default per protocol: kvh-a/b/c 921600, "
                       "dsp3000 38400, lines 115200)")
    g.add_argument("--protocol", choices=PROTOCOLS, help="serial protocol: kvh-a|kvh-b|kvh-c = KVH DSP-1750/1760/1775 "
                   "binary formats A/B/C, dsp3000 = KVH DSP-3000 ASCII (deg/s), lines = ASCII/CSV lines with "
                   "--columns (default for --serial: kvh-a; a raw capture takes it from its .json sidecar)")
    g.add_argument("--kvh-rot", choices=("rate", "delta"), help="what the gyro outputs: rate (units/s) or delta "
                   "angle (units per sample) (default: delta for kvh-*, rate for dsp3000)")
    g.add_argument("--kvh-units", choices=("deg", "rad"), help="angle unit of KVH binary output (default: rad)")
    g.add_argument("--axis", choices=("x", "y", "z"), help="KVH gyro axis to monitor (default: z)")
    g.add_argument("--columns", metavar="MAP", help="lines protocol: comma-separated name of every field in order, "
                   "exactly one rate column (rate_dph, rate_dps, rate_rps, delta_deg, delta_rad, delta_arcsec), "
                   "optional seq or seq:N (counter wrapping at N), valid, '-' to ignore, any other name = aux "
                   "channel (temp_c deg C, vib_g g, ...) (default: rate_dph)")
    g.add_argument("--rate-hz", type=number(0, MAX_RATE_HZ, above=True), metavar="HZ", help="sample rate in Hz "
                   f"where the protocol does not tell it, > 0 and <= {MAX_RATE_HZ:g} (default: kvh-* 1000, dsp3000 100, lines 100; CAN: the DBC message cycle time)")
    c = parser.add_argument_group("CAN gyro" if live else "CAN log decoding")
    if live:
        c.add_argument("--can", metavar="CHANNEL", help="CAN channel of the gyro (can0, PCAN_USBBUS1, ...)")
        c.add_argument("--interface", default="socketcan", metavar="I", help="python-can interface: socketcan, "
                       "pcan, kvaser, vector, slcan, virtual, ... (default: socketcan)")
        c.add_argument("--can-bitrate", type=number(1_000, 8_000_000, integer=True), metavar="BPS",
                       help="CAN bit rate in bit/s, 1,000..8,000,000, for interfaces that set it (default: leave the interface as configured)")
    c.add_argument("--dbc", metavar="F", help="DBC file describing the gyro's CAN frames (see "
                   "fogmon/data/gyro_example.dbc)")
    c.add_argument("--can-message", metavar="NAME", help="DBC message carrying the rate (default: the message "
                   "holding --can-rate; required if several do)")
    c.add_argument("--can-rate", metavar="SIGNAL", help="DBC signal with the angular rate "
                   "(default: rate); its DBC unit (deg/h, deg/s, rad/s, deg, rad, arcsec) sets the conversion")
    c.add_argument("--can-rate-unit", metavar="UNIT", help="override the rate signal's DBC unit: deg/h, deg/s, "
                   "rad/s (rates) or deg, rad, arcsec (angle per sample)")
    c.add_argument("--can-temp", metavar="SIGNAL", help="DBC signal with the temperature in deg C "
                   "(default: temperature if the message has it)")
    c.add_argument("--can-counter", metavar="SIGNAL", help="DBC signal with the rolling counter used for gap "
                   "detection (default: counter if the message has it)")
    c.add_argument("--can-valid", metavar="SIGNAL", help="DBC signal that is nonzero when the sample is valid "
                   "(default: valid if the message has it)")
    parser.add_argument("--max-rate-dph", type=positive, metavar="X",
                        help="plausibility gate in deg/h: a rate beyond +-X is a corrupt value, not data; the "
                             "sample becomes invalid and is counted (implausible_samples) and reported. Default: "
                             f"the device's full scale x {pl.MARGIN:g}: kvh-a/b/c "
                             f"{pl.KVH_DSP17XX_MAX_ABS_DPH:,.0f} ({pl.KVH_DSP17XX_FULL_SCALE_DPH / 3600:g} deg/s), "
                             f"dsp3000 {pl.KVH_DSP3000_MAX_ABS_DPH:,.0f} ({pl.KVH_DSP3000_FULL_SCALE_DPH / 3600:g} "
                             f"deg/s); lines, CAN and replay logs {pl.GENERIC_MAX_ABS_DPH:,.0f} "
                             f"({pl.GENERIC_MAX_ABS_DPH / 3600:,.0f} deg/s). Raw captures replay with the value "
                             "their sidecar recorded unless given")
    if replay:
        parser.add_argument("--tolerate-bad-rows", action="store_true", help="replay log: skip and count bad rows "
                       "instead of stopping at the first one")


def _get(args, name, default=None):
    v = getattr(args, name, None)
    return default if v is None else v


def codec_options(args) -> dict:
    """Decoder options given on the command line (None = not given)."""
    return {"protocol": _get(args, "protocol"), "rate_hz": _get(args, "rate_hz"),
            "kvh_rot": _get(args, "kvh_rot"), "kvh_units": _get(args, "kvh_units"),
            "axis": _get(args, "axis"), "columns": _get(args, "columns"),
            "max_rate_dph": _get(args, "max_rate_dph")}


def can_options(args) -> dict:
    """CAN decoding options given on the command line."""
    return {"message": _get(args, "can_message"), "rate_signal": _get(args, "can_rate"),
            "rate_unit": _get(args, "can_rate_unit"), "temp_signal": _get(args, "can_temp"),
            "counter_signal": _get(args, "can_counter"), "valid_signal": _get(args, "can_valid"),
            "rate_hz": _get(args, "rate_hz"), "max_rate_dph": _get(args, "max_rate_dph")}


def open_live_source(args):
    """The live source named by ``--serial`` or ``--can`` (exactly one)."""
    serial_port, can_channel = _get(args, "serial"), _get(args, "can")
    if bool(serial_port) == bool(can_channel):
        raise FogmonError("give exactly one of --serial PORT or --can CHANNEL")
    if serial_port:
        from fogmon.sources.serial_source import SerialSource
        o = codec_options(args)
        protocol = o.pop("protocol") or "kvh-a"
        codec = make_codec(protocol, **{k: v for k, v in o.items() if v is not None})
        return SerialSource(serial_port, _get(args, "baud", DEFAULTS[protocol][0]), codec)
    from fogmon.sources.can_source import CanSource, load_dbc
    if not _get(args, "dbc"):
        raise FogmonError("--can needs --dbc F describing the gyro's frames (example: fogmon/data/gyro_example.dbc)")
    return CanSource(can_channel, _get(args, "interface", "socketcan"), load_dbc(args.dbc),
                     bitrate=_get(args, "can_bitrate"), dbc_path=args.dbc, **can_options(args))


def _sniff(path: str) -> str:
    """'replay-log', 'can-csv' or 'other' from the first non-empty line."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError as e:
        raise FogmonError(f"{path}: cannot read: {e.strerror}") from None
    for raw in head.splitlines():
        s = raw.strip()
        if not s:
            continue
        if s.startswith(b"# fogmon replay log") or (b"time_s" in s and b"rate_dph" in s):
            return "replay-log"
        if s.startswith(b"timestamp,arbitration_id"):
            return "can-csv"
        if s.startswith(b"#"):
            continue
        return "other"
    return "other"


def open_replay_source(path: str, args):
    """A source replaying ``path``: a replay-log CSV, a raw serial capture (protocol from
    ``--protocol`` or its ``.json`` sidecar), a CAN log (.asc .blf .trc .csv .log with
    ``--dbc`` or a sidecar), or an archive folder (``open_archive``). Not paced: the
    pipeline paces (``--realtime``)."""
    from fogmon.sources.replay import ReplayLogSource, open_raw_capture, read_sidecar
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FogmonError(f"{path}: no such file")
    if os.path.isdir(path):
        return open_archive(path, args)
    if os.path.splitext(path)[1].lower() == ".toml":  # a sensor model: stream its simulation (endless)
        from fogmon.sources.simulated import SimulatedSource
        return SimulatedSource(path)
    if os.path.splitext(path)[1].lower() == ".parquet":  # a Parquet replay log (fogmon.parquet_log)
        from fogmon.sources.parquet import ParquetLogSource
        return ParquetLogSource(path, tolerate=bool(_get(args, "tolerate_bad_rows", False)),
                                max_abs_dph=_get(args, "max_rate_dph", pl.GENERIC_MAX_ABS_DPH))
    side = read_sidecar(path)
    ext = os.path.splitext(path)[1].lower()
    kind = _sniff(path) if not side else side.get("kind")
    if kind == "can" or ext in CAN_LOG_SUFFIXES or kind == "can-csv":
        from fogmon.sources.can_source import open_can_log
        return open_can_log(path, _get(args, "dbc"), can_options(args), side)
    if kind == "serial" or (_get(args, "protocol") and kind != "replay-log"):
        return open_raw_capture(path, codec_options(args))
    if kind == "replay-log" or ext == ".csv":
        return ReplayLogSource(path, tolerate=bool(_get(args, "tolerate_bad_rows", False)),
                               max_abs_dph=_get(args, "max_rate_dph", pl.GENERIC_MAX_ABS_DPH))
    raise FogmonError(f"{path}: not a replay log; for a raw serial capture give --protocol "
                      f"({', '.join(PROTOCOLS)}), for a CAN log use .asc/.blf/.trc/.csv/.log with --dbc")


def open_archive(directory: str, args):
    """An archive folder (fogmon monitor --archive) as one recording: its replay-log pieces
    samples-NNNN.csv in order; or, when the folder has none or the command line gives
    decoder options (--protocol, --kvh-*, --axis, --columns, --rate-hz, --dbc, --can-*)
    to decode it again, its raw capture pieces (raw-NNNN.bin or frames-NNNN.asc) as one
    stream. One piece alone is replayed by naming its file. ``--max-rate-dph`` gates
    whichever is replayed and does not by itself ask for decoding again."""
    from fogmon.pieces import find_pieces, piece_path
    from fogmon.sinks.archive import CAN_CAPTURE, REPLAY_LOG, SERIAL_CAPTURE
    from fogmon.sinks.parquet_pieces import piece_files
    from fogmon.sources.replay import ReplayLogSet, ReplayLogSource, open_raw_capture, read_sidecar

    logs = find_pieces(directory, REPLAY_LOG) or piece_files(directory)
    serial, frames = find_pieces(directory, SERIAL_CAPTURE), find_pieces(directory, CAN_CAPTURE)
    decode = any(v is not None for k, v in (*codec_options(args).items(), *can_options(args).items(),
                                            ("dbc", _get(args, "dbc"))) if k != "max_rate_dph")
    if serial and (decode or not logs):
        return open_raw_capture(serial, codec_options(args))
    if frames and (decode or not logs):
        from fogmon.sources.can_source import open_can_log
        sides = [read_sidecar(p) or {} for p in frames]
        fields = ("message", "rate_signal", "rate_unit", "temp_signal", "counter_signal", "valid_signal", "rate_hz",
                  "max_rate_dph", "dbc")
        for p, side in zip(frames[1:], sides[1:]):
            if any(side.get(k) != sides[0].get(k) for k in fields):
                raise FogmonError(f"{p}: its sidecar's decoder options or DBC differ from {frames[0]}'s: "
                                  f"not pieces of one CAN log")
        return open_can_log(frames, _get(args, "dbc"), can_options(args), sides[0])
    tolerate = bool(_get(args, "tolerate_bad_rows", False))
    max_abs_dph = _get(args, "max_rate_dph", pl.GENERIC_MAX_ABS_DPH)
    if logs and logs[0].endswith(".parquet"):  # Parquet pieces (and parts of a piece never joined): one recording
        from fogmon.sources.parquet import ParquetLogSource
        return ParquetLogSource(logs, tolerate=tolerate, max_abs_dph=max_abs_dph)
    if len(logs) == 1:
        return ReplayLogSource(logs[0], tolerate=tolerate, max_abs_dph=max_abs_dph)
    if logs:
        return ReplayLogSet(logs, tolerate=tolerate, max_abs_dph=max_abs_dph)
    raise FogmonError(f"{directory}: is a folder without an archive (no pieces of {REPLAY_LOG}, samples.parquet, "
                      f"{SERIAL_CAPTURE} or {CAN_CAPTURE} such as {piece_path(REPLAY_LOG, 1)}); give a replay log, raw capture "
                      f"or CAN log")
