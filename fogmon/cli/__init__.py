"""The `fogmon` command: a thin dispatcher. Each sub-command lives in its own module
``fogmon.cli.<name>`` exposing ``add_arguments(parser)`` and ``run(args) -> int``;
modules are imported only when their command runs, so ``--help`` is fast.

Library messages name parameters in backticks (fogmon.errors); the command shows them as
its flags (``command_flags``): every FogmonError and FogmonWarning is rendered so."""
from __future__ import annotations

import argparse
import functools
import importlib
import os
import sys
import warnings
from collections.abc import Iterable

from fogmon import __version__, startup, stopping
from fogmon.errors import NAME, FogmonError, FogmonWarning, render_names

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
    "info": "what a recording or log holds: one line per topic/channel/signal/column (type, count, rate, span, unit)",
}


#: library parameter name -> the dest of the option that sets it, where the two differ
ALIASES = {
    "n_boot": "bootstrap",        # fogmon.explain Options.n_boot: explain --bootstrap
    "thermal": "thermal_cal",     # fogmon.methods.live LiveMethods.thermal: --thermal-cal
    "rrd_path": "rrd",            # the Rerun sink's rrd_path: --rrd
    "n_samples": "record_s",      # fogmon.davar.curve adev_from_curve(n_samples=): fit --record-s
}

#: backticked names in library messages that no option sets: shown as written
NO_FLAG = frozenset({
    "rerun",                      # the Rerun viewer program (fogmon.sinks.rerun_sink)
    "exclude_motion",             # fogmon.oadev / dadev (fogmon.api); the commands' --keep-motion is its inverse
    "limits",                     # fogmon.davar.fit.fit_curve (Python only: which intervals to compute)
})


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):
        """A usage error: one line naming the command and where its help is, exit 2
        (not argparse's usage block: the one line that matters would scroll away)."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_args(self, args=None, namespace=None):  # type: ignore[override]
        """As argparse's, with arguments no option takes reported by the command's own
        parser (its prog and help named), not by the top-level one."""
        ns, extra = self.parse_known_args(args, namespace)
        if extra:
            commands = getattr(self, "commands", {})
            commands.get(getattr(ns, "command", None), self).error(f"unrecognized arguments: {' '.join(extra)}")
        return ns


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    p = _Parser(prog="fogmon", description="Real-time streaming monitor for fiber-optic gyroscopes. "
                "Rates in deg/h, times in s, IEEE-952 coefficients in their units "
                "(Q arcsec, N deg/sqrt(h), B deg/h, K deg/h/sqrt(h), R deg/h^2).")
    p.add_argument("--version", action="version", version=f"fogmon {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    # Only the sub-command being run imports its module (fast --help).
    wanted = next((a for a in argv if not a.startswith("-")), None)
    p.commands = {}  # type: ignore[attr-defined]
    for name, help_text in COMMANDS.items():
        sp = sub.add_parser(name, help=help_text, description=help_text)
        p.commands[name] = sp  # type: ignore[attr-defined]
        if name == wanted:
            importlib.import_module(f"fogmon.cli.{name}").add_arguments(sp)
    return p


def flag_table(parser: argparse.ArgumentParser) -> dict[str, str]:
    """dest -> long option string (``--rate-hz``) of every option of ``parser``."""
    out: dict[str, str] = {}
    for action in parser._actions:
        long = [s for s in action.option_strings if s.startswith("--")]
        if long:
            out.setdefault(action.dest, long[0])
    return out


@functools.cache
def _options(command: str) -> dict[str, str]:
    """dest -> flag of `fogmon COMMAND`'s options (its parser built once, when needed)."""
    p = _Parser(prog=f"fogmon {command}")
    importlib.import_module(f"fogmon.cli.{command}").add_arguments(p)
    return flag_table(p)


def command_flags(command: str, names: Iterable[str] = ()) -> dict[str, str]:
    """Parameter name -> flag for rendering the messages of `fogmon COMMAND`: its own
    options (dest -> flag) and their ALIASES; a name of ``names`` it lacks is taken from
    another command's options (a message telling to run that command with its option),
    whose parsers are built only then, or else shown as written (in backticks)."""
    own = _options(command)
    table = {**{name: own[dest] for name, dest in ALIASES.items() if dest in own}, **own}
    missing = {n for n in names if n not in table} - NO_FLAG
    # explain last: its parser imports the explainer (seconds) for its defaults
    for other in sorted(COMMANDS, key=lambda c: c == "explain"):
        if not missing:
            break
        if other != command:
            theirs = _options(other)
            table.update({n: theirs[n] for n in missing & theirs.keys()})
            missing -= theirs.keys()
    return {**{n: f"`{n}`" for n in names if n not in table}, **table}


def render(message: str | FogmonError | FogmonWarning, command: str) -> str:
    """A library message (its parameter names in backticks) as `fogmon COMMAND` shows
    it: each name as the command's flag for it."""
    text = message.message if isinstance(message, (FogmonError, FogmonWarning)) else str(message)
    return render_names(text, command_flags(command, NAME.findall(text)))


def _one_line_warnings(command: str, show):
    """A ``warnings.showwarning`` that prints FogmonWarnings as one line on stderr
    (parameter names as flags) and hands other warnings to ``show``."""
    def showwarning(message, category, *args, **kwargs):
        if issubclass(category, FogmonWarning):
            print(f"fogmon {command}: warning: {render(message, command)}", file=sys.stderr)
        else:
            show(message, category, *args, **kwargs)
    return showwarning


#: the exit status of a command whose output's reader went away (`fogmon ... | head`):
#: what a shell reports for a program killed by SIGPIPE, 128 + 13
BROKEN_PIPE_EXIT = 141


def main(argv: list[str] | None = None) -> int:
    """The fogmon program: run the command ``argv`` (None: the process's arguments);
    the exit status (0 done, 2 a user's mistake, BROKEN_PIPE_EXIT when the console's
    reader closed its end, as `| head` does: no traceback; outputs are complete or not
    written either way)."""
    try:
        return _main(argv)
    except BrokenPipeError:
        # the interpreter flushes stdout at exit again: point it at /dev/null first
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return BROKEN_PIPE_EXIT


def _main(argv: list[str] | None) -> int:
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
        print(f"fogmon {args.command}: error: {render(e, args.command)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"fogmon {args.command}: interrupted ({stopping.stop_name()})", file=sys.stderr)
        return stopping.interrupted_exit_code()


if __name__ == "__main__":
    sys.exit(main())
