"""What each `fogmon` command writes and reads, from its options: the one output check
(fogmon.outputs.check_outputs) that every command runs before any work. A command
whose options write nothing (inorbit, updown, info) has no output to check."""
from __future__ import annotations

import argparse
import os
from collections.abc import Iterable

from fogmon.outputs import Output, check_outputs

#: options (dests) naming a file or folder a command reads
INPUT_OPTIONS = ("recording", "input", "curve", "model", "like", "thermal_cal", "dbc", "up", "down", "serial")


def rotated(args: argparse.Namespace) -> bool:
    """The .rrd is written in numbered pieces: ``--rotate-s S`` given with S > 0."""
    return bool(getattr(args, "rotate_s", None))


def command_outputs(args: argparse.Namespace) -> list[Output]:
    """Every file and folder ``args.command`` will write, as the options ask."""
    command = args.command
    out: list[Output] = []
    if command == "monitor":   # the run's own archive folder is made in this one
        out.append(Output("`archive`", args.archive or ".", folder=True, create=False))
    if command == "sim":
        out.append(Output("`out`", args.out))
    if command == "convert":
        out.append(Output("OUT", args.output))
    if command == "batch":
        out += _batch_outputs(args)
    if command == "explain":
        from fogmon.explain.report import outliers_path

        out += [Output("`report`", args.report),
                Output("`report` (its PNG)", os.path.splitext(args.report)[0] + ".png"),
                Output("`report` (its outliers list)", outliers_path(args.report))]
    rrd = getattr(args, "rrd", None)
    if rrd:
        out.append(Output("`rrd`", rrd, pieces=command in ("replay", "monitor") and rotated(args)))
    for dest in ("out_model", "out_corrected"):
        if getattr(args, dest, None):
            out.append(Output(f"`{dest}`", getattr(args, dest)))
    export = getattr(args, "export", None)
    if export:
        out.append(Output(f"`export` {export[0]}", export[1]))
    return out


def _batch_outputs(args: argparse.Namespace) -> list[Output]:
    """batch: the --out folder (created in an existing one) and its two tables, the
    fleet report and the files beside it."""
    from fogmon.fleet import tables
    from fogmon.fleet.report import report_files

    out = [Output("`out`", args.out, folder=True)]
    new = not os.path.isdir(args.out)      # made by the run: nothing in it yet to check
    if not new:
        out += [Output("`out`", os.path.join(args.out, name)) for name in (tables.WINDOWS, tables.RECORDINGS)]
    in_new = new and os.path.dirname(os.path.abspath(args.report or "")) == os.path.abspath(args.out)
    if args.report and not in_new:
        out += [Output("`report`" + (" (beside it)" if i else ""), p) for i, p in enumerate(report_files(args.report))]
    return out


def command_inputs(args: argparse.Namespace) -> list[str]:
    """Every file or folder named by ``args``'s input options (a live device's port too)."""
    return [v for dest in INPUT_OPTIONS if isinstance(v := getattr(args, dest, None), str)]


def check_command_outputs(args: argparse.Namespace, inputs: Iterable[str] = ()) -> None:
    """The one output check of every command, before any work: FogmonError naming the
    option unless every output can be written without touching an input (the command's
    input options and ``inputs``, such as batch's expanded recordings); fogmon.outputs."""
    check_outputs(command_outputs(args), [*command_inputs(args), *inputs])
