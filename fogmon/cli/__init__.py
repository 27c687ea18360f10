"""The `fogmon` command: a thin dispatcher. Each sub-command lives in its own module
``fogmon.cli.<name>`` exposing ``add_arguments(parser)`` and ``run(args) -> int``;
modules are imported only when their command runs, so ``--help`` is fast."""
from __future__ import annotations

import argparse
import importlib
import sys
import warnings

from fogmon import __version__, startup, stopping
from fogmon.errors import FogmonError, FogmonWarning

#: sub-command -> one-line help
COMMANDS = {
    "sim": "simulate a sensor model (TOML) into a replay log, optionally --like a recording",
    "replay": "stream a recording (replay log, raw serial capture, CAN log) through DAVAR into Rerun",
    "monitor": "monitor a live gyro on a serial port or CAN bus, archive everything, stream to Rerun",
    "explain": "locate where a recording and a sensor model disagree, name and fit the missing physics",
    "thermal": "calibrate thermal drift K0(T) + K1 dT/dt + K2 d2T/dt2 from a recording with temp_c and correct it",
    "inorbit": "in-orbit evaluation: ARW from Pauta-cleaned differences, per-orbit bias instability, wavelet bands",
    "fit": "IEEE-952 fit (with intervals) of an Allan-deviation curve made by another tool; --export kalibr|matlab|ros",
    "updown": "bias and scale-factor error from axis-up and axis-down recordings against Earth rate",
    "convert": "convert a recording (replay log, raw capture, CAN log, archive) to a Parquet replay log",
    "batch": "analyse many recordings on Dask into windows.parquet + recordings.parquet (fleet report optional)",
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2 (argparse prints usage too)
        self.print_usage(sys.stderr)
        self.exit(2, f"fogmon: error: {message}\n")


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    p = _Parser(prog="fogmon", description="Real-time streaming monitor for fiber-optic gyroscopes. "
                "Rates in deg/h, times in s, IEEE-952 coefficients in their units "
                "(Q arcsec, N deg/sqrt(h), B deg/h, K deg/h/sqrt(h), R deg/h^2).")
    p.add_argument("--version", action="version", version=f"fogmon {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    # Only the sub-command being run imports its module (fast --help).
    wanted = next((a for a in argv if not a.startswith("-")), None)
    for name, help_text in COMMANDS.items():
        sp = sub.add_parser(name, help=help_text, description=help_text)
        if name == wanted:
            importlib.import_module(f"fogmon.cli.{name}").add_arguments(sp)
    return p


def _one_line_warnings(command: str, show):
    """A ``warnings.showwarning`` that prints FogmonWarnings as one line on stderr and
    hands other warnings to ``show``."""
    def showwarning(message, category, *args, **kwargs):
        if issubclass(category, FogmonWarning):
            print(f"fogmon {command}: warning: {message}", file=sys.stderr)
        else:
            show(message, category, *args, **kwargs)
    return showwarning


def main(argv: list[str] | None = None) -> int:
    if argv is None:   # the fogmon program itself, not a caller's process (fogmon.startup)
        startup.own_process()
    argv = sys.argv[1:] if argv is None else list(argv)
    with startup.loading():   # the command's module and its libraries
        args = build_parser(argv).parse_args(argv)
    try:
        with stopping.installed(), warnings.catch_warnings():  # SIGTERM/SIGHUP stop a command as Ctrl-C does
            warnings.simplefilter("default", FogmonWarning)  # each distinct warning once
            warnings.showwarning = _one_line_warnings(args.command, warnings.showwarning)
            return int(importlib.import_module(f"fogmon.cli.{args.command}").run(args) or 0)
    except FogmonError as e:
        print(f"fogmon {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"fogmon {args.command}: interrupted ({stopping.stop_name()})", file=sys.stderr)
        return stopping.interrupted_exit_code()


if __name__ == "__main__":
    sys.exit(main())
