"""Command-line options of the sources (`fogmon replay`, `fogmon monitor`) and the
SourceOptions they build: the only place that reads them from an argparse namespace."""
from __future__ import annotations

import argparse
from dataclasses import fields

from fogmon.block import parse_axes
from fogmon.cli.values import number, positive
from fogmon.errors import FogmonError
from fogmon.formats.recording import MAX_SAMPLE_RATE_HZ
from fogmon.sources import plausibility as pl
from fogmon.sources.codecs.kvh import ACCEL_UNITS
from fogmon.sources.codecs.protocols import PROTOCOLS
from fogmon.sources.options import SourceOptions

#: The highest --rate-hz accepted (Hz): beyond any gyro's output rate (FOGs stop near 10 kHz).
MAX_RATE_HZ = MAX_SAMPLE_RATE_HZ


def add_source_arguments(parser: argparse.ArgumentParser, mode: str = "both") -> None:
    """Add the source options. ``mode`` 'live' (monitor), 'replay' or 'both': live adds
    ``--serial``/``--can`` and the port/bus options; replay adds ``--tolerate-bad-rows``;
    decoder options (``--protocol``, ``--dbc``...) go to both. Pacing (``--realtime``) and
    ``--duration-s`` belong to the pipeline (fogmon.pipeline)."""
    live, replay = mode in ("live", "both"), mode in ("replay", "both")
    _add_serial_arguments(parser.add_argument_group("serial gyro" if live else "raw serial capture decoding"), live)
    _add_can_arguments(parser.add_argument_group("CAN gyro" if live else "CAN log decoding"), live)
    parser.add_argument("--max-rate-dph", type=positive, metavar="DEG/H",
                        help="plausibility gate in deg/h: a rate beyond +-DEG/H is a corrupt value, not data; the "
                             "sample becomes invalid and is counted (implausible_samples) and reported. Default: "
                             f"the device's full scale x {pl.MARGIN:g}: kvh-a/b/c "
                             f"{pl.KVH_DSP17XX_MAX_ABS_DPH:,.0f} ({pl.KVH_DSP17XX_FULL_SCALE_DPH / 3600:g} deg/s), "
                             f"dsp3000 {pl.KVH_DSP3000_MAX_ABS_DPH:,.0f} ({pl.KVH_DSP3000_FULL_SCALE_DPH / 3600:g} "
                             f"deg/s); lines, CAN and replay logs {pl.GENERIC_MAX_ABS_DPH:,.0f} "
                             f"({pl.GENERIC_MAX_ABS_DPH / 3600:,.0f} deg/s). Raw captures replay with the value "
                             "their sidecar recorded unless given. A sample beyond 1e8 deg/h (the Allan engine's "
                             "ceiling) that a higher gate lets through makes the Allan terms spanning it inf")
    if replay:
        parser.add_argument("--tolerate-bad-rows", action="store_true", help="replay log: skip and count bad rows "
                       "instead of stopping at the first one")


def _add_serial_arguments(g, live: bool) -> None:
    """The serial device (live) and serial decoder options."""
    if live:
        g.add_argument("--serial", metavar="PORT", help="serial port of the gyro (/dev/ttyUSB0, COM3, or a "
                       "pyserial URL such as loop:// or socket://HOST:PORT); reopened with backoff if it disappears")
        g.add_argument("--baud", type=number(1, 50_000_000, integer=True), metavar="BAUD", help="baud rate, "
                       "1..50,000,000 (default per protocol: kvh-a/b/c 921600, "
                       "dsp3000 38400, lines 115200)")
    g.add_argument("--protocol", choices=PROTOCOLS, metavar="PROTOCOL",
                   help="serial protocol: kvh-a|kvh-b|kvh-c = KVH DSP-1750/1760/1775 "
                   "binary formats A/B/C, dsp3000 = KVH DSP-3000 ASCII (deg/s), lines = ASCII/CSV lines with "
                   "--columns (default for --serial: kvh-a; a raw capture takes it from its .json sidecar)")
    g.add_argument("--kvh-rot", choices=("rate", "delta"), help="what the gyro outputs: rate (units/s) or delta "
                   "angle (units per sample) (default: delta for kvh-*, rate for dsp3000)")
    g.add_argument("--kvh-units", choices=("deg", "rad"), help="angle unit of the KVH gyros' output (default: rad)")
    g.add_argument("--kvh-accel", choices=tuple(ACCEL_UNITS), help="what the KVH accelerometers output (aux "
                   "channels accel_<axis>_g, converted to g): g = acceleration in g (the device's default), "
                   "dv-m / dv-ft = velocity increment per sample in m/s / ft/s (=LINFMT delta), none = leave "
                   "them out (a gyro-only DSP-1760) (default: g)")
    g.add_argument("--axis", type=axis_list, metavar="AXES", help="KVH gyros to decode: one of x, y, z (a "
                   "one-axis stream, as before) or several separated by commas (x,y) (default: all three, a "
                   "three-axis stream x,y,z with the accelerometers); the axes of a multi-axis replay log "
                   "(rate_<axis>_dph columns) to analyse (default: every axis); the gyros of a ROS bag or PX4 ULog "
                   "IMU, x, y, z, one or several (default: all three)")
    g.add_argument("--columns", metavar="NAMES", help="lines protocol: comma-separated name of every field in order, "
                   "exactly one rate column (rate_dph, rate_dps, rate_rps, delta_deg, delta_rad, delta_arcsec), "
                   "optional seq or seq:N (counter wrapping at N), valid, '-' to ignore, any other name = aux "
                   "channel (temp_c deg C, vib_g g, ...) (default: rate_dph)")
    _add_rate_hz(g)


def _add_rate_hz(g) -> None:
    g.add_argument("--rate-hz", dest="sample_rate_hz", type=number(0, MAX_RATE_HZ, above=True), metavar="HZ",
                   help=f"sample rate in Hz, > 0 and <= {MAX_RATE_HZ:g}: where the protocol does not tell it "
                        "(default: kvh-* 1000, dsp3000 100, lines 100); for files with time stamps (CAN logs, "
                        "bags, ULog, MDF4, LAS) only checked against the rate the stamps give (more than 1 %% "
                        "off: an error, unless --force-rate)")


def _add_can_arguments(c, live: bool) -> None:
    """The CAN bus (live) and CAN decoder (DBC) options."""
    if live:
        c.add_argument("--can", metavar="CHANNEL", help="CAN channel of the gyro (can0, PCAN_USBBUS1, ...)")
        c.add_argument("--interface", default=SourceOptions.interface, metavar="INTERFACE",
                       help="python-can interface: "
                       f"socketcan, pcan, kvaser, vector, slcan, virtual, ... (default: {SourceOptions.interface})")
        c.add_argument("--can-bitrate", type=number(1_000, 8_000_000, integer=True), metavar="BIT/S",
                       help="CAN bit rate in bit/s, 1,000..8,000,000, for interfaces that set it (default: "
                            "leave the interface as configured)")
    c.add_argument("--dbc", metavar="GYRO.dbc", help="DBC file describing the gyro's CAN frames (see "
                   "fogmon/data/gyro_example.dbc)")
    c.add_argument("--can-message", metavar="NAME", help="DBC message carrying the rate (default: the message "
                   "holding --can-rate, or its first axis's signal; required if several do)")
    c.add_argument("--can-rate", metavar="SIGNAL", help="DBC signal with the angular rate "
                   "(default: rate); its DBC unit (deg/h, deg/s, rad/s, deg, rad, arcsec) sets the conversion. "
                   "Several axes: AXIS=SIGNAL,... (x=GyroX,y=GyroY,z=GyroZ), possibly in different messages: the "
                   "first axis's message is the sample clock, each other axis takes its message's latest frame "
                   "since the previous clock frame, and is invalid (counted) for a sample without one "
                   "(docs/sources.md)")
    c.add_argument("--can-rate-unit", metavar="UNIT", help="override the rate signal's DBC unit: deg/h, deg/s, "
                   "rad/s (rates) or deg, rad, arcsec (angle per sample)")
    c.add_argument("--can-temp", metavar="SIGNAL", help="DBC signal with the temperature in deg C "
                   "(default: temperature if the message has it)")
    c.add_argument("--can-counter", metavar="SIGNAL", help="DBC signal with the rolling counter used for gap "
                   "detection (default: counter if the message has it)")
    c.add_argument("--can-valid", metavar="SIGNAL", help="DBC signal that is nonzero when the sample is valid "
                   "(default: valid if the message has it)")


def axis_list(text: str) -> str:
    """argparse ``type=`` of ``--axis``: an axis name (letters and digits) or a comma list
    of them, kept as given (fogmon.block.parse_axes)."""
    try:
        parse_axes(text)
    except FogmonError as e:
        raise argparse.ArgumentTypeError(str(e).split(": ", 1)[1]) from None
    return text


def source_options(args: argparse.Namespace) -> SourceOptions:
    """The SourceOptions of parsed source options (``add_source_arguments``; options a
    command does not have keep their defaults)."""
    given = vars(args)
    return SourceOptions(**{f.name: given[f.name] for f in fields(SourceOptions)
                            if given.get(f.name) is not None})


def _has(parser: argparse.ArgumentParser, flag: str) -> bool:
    return flag in parser._option_string_actions   # an option another group of the command already added


def add_reader_arguments(parser: argparse.ArgumentParser, axis: bool = True) -> None:
    """The one set of reader options (CONTRACT section 3), for every command that reads
    recordings: ``--topic``, ``--channel``, ``--time-channel``, ``--rate-unit``,
    ``--resample-hz``, ``--force-rate`` and, unless the command's source options already
    have them, ``--axis`` (``axis``), ``--rate-hz`` and the CAN log options (``--dbc``,
    ``--can-rate``, ...)."""
    g = parser.add_argument_group("reading a recording (ROS bag/MCAP, PX4 ULog, MDF4, LAS, CAN logs; "
                                  "docs/readers.md; fogmon info FILE lists what a file holds)")
    g.add_argument("--topic", metavar="NAME", help="ROS bag/MCAP: the sensor_msgs/Imu topic (default: the only "
                   "one); PX4 ULog: sensor_combined or sensor_gyro, NAME:INSTANCE for another instance (default: "
                   "the one with the most samples)")
    if axis and not _has(parser, "--axis"):
        g.add_argument("--axis", type=axis_list, metavar="NAME", help="the axis to analyse, or a comma list (x,y): "
                       "gyros x, y, z of a ROS bag or PX4 ULog IMU, axes of a multi-axis replay log "
                       "(rate_<axis>_dph columns) (default: every axis)")
    g.add_argument("--channel", metavar="NAME", help="MDF4: the rate channel (unit from the file); LAS: the rate "
                   "curve (default: the only curve with a rate unit)")
    g.add_argument("--accel-channel", dest="accel_channels", metavar="NAMES", help="MDF4: accelerometer channels "
                   "(unit from the file: m/s^2, g, mg), a comma list, named x, y, z in that order or AXIS=NAME each; "
                   "fitted as IEEE Std 1293 terms beside the gyro (docs/readers.md)")
    g.add_argument("--time-channel", metavar="NAME", help="LAS: the time curve: seconds, a clock (HHMMSS) or "
                   "date-times (default: the index curve when it is a time; a depth-indexed file needs it)")
    g.add_argument("--rate-unit", metavar="UNIT", help="MDF4/LAS: the rate's unit when the file does not say "
                   "it or says it wrongly: deg/h, deg/s, rad/s")
    g.add_argument("--resample-hz", type=number(0, MAX_RATE_HZ, above=True), metavar="HZ", help="files with time "
                   "stamps: block means on a uniform HZ grid (each 1/HZ s block: the mean of the samples stamped "
                   "in it; a block without one is a gap) for irregular logging (alternating steps, many gaps), "
                   "which is refused otherwise; the Allan deviation then starts at 1/HZ s (docs/readers.md)")
    g.add_argument("--force-rate", action="store_true", help="use --rate-hz, the DBC cycle time or a replay "
                   "log's sample_rate_hz although the time stamps say another rate (they place the samples; "
                   "their clock is scaled to the rate given)")
    if not _has(parser, "--rate-hz"):
        _add_rate_hz(g)
    if not _has(parser, "--dbc"):
        _add_can_arguments(parser.add_argument_group("CAN log decoding"), live=False)
