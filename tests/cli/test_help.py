"""Every command's --help (issue 31.5): examples and exit codes in its epilog, every
example a command line the parser accepts, metavars in words (a unit or a file name,
never argparse's DEST or a single letter), and a usage error one line naming where the
help is."""
import argparse
import importlib
import re
import shlex

import pytest

from fogmon.cli import COMMANDS, _Parser, build_parser, main
from fogmon.cli.helptext import example_commands


def parser_of(command: str) -> argparse.ArgumentParser:
    p = _Parser(prog=f"fogmon {command}")
    importlib.import_module(f"fogmon.cli.{command}").add_arguments(p)
    return p


@pytest.mark.parametrize("command", list(COMMANDS))
def test_help_has_examples_that_parse_and_exit_codes(command):
    p = parser_of(command)
    assert "\nexit codes:\n  0 " in p.epilog and p.epilog.startswith("examples:\n")
    examples = example_commands(p)
    assert len(examples) >= 2
    for line in examples:
        argv = shlex.split(line)[1:]
        assert argv[0] == command
        build_parser(argv).parse_args(argv)         # raises SystemExit if the example does not parse


@pytest.mark.parametrize("command", list(COMMANDS))
def test_metavars_are_words(command):
    bad = []
    for a in parser_of(command)._actions:
        if a.nargs == 0 or isinstance(a, argparse._HelpAction):
            continue
        if a.metavar is None and a.choices:
            continue                                    # shown as {choice,choice}
        names = a.metavar if isinstance(a.metavar, tuple) else (a.metavar,)
        for mv in names:
            if mv is None or "_" in mv or (re.fullmatch(r"[A-Z]{1,2}", mv) and mv != "HZ"):
                bad.append((a.option_strings or a.dest, mv))
    assert bad == []


@pytest.mark.parametrize("argv", [["replay"], ["replay", "x.csv", "--window-s", "0"], ["thermal", "x.csv", "--bogus"],
                                  ["sim", "--model", "m.toml"], ["explain", "x.csv"], ["batch", "--out", "d"],
                                  ["updown", "--up", "u.csv"], ["fit", "c.csv", "--confidence", "2"],
                                  ["inorbit", "x.csv", "--pauta-k", "1"], ["convert", "a.csv"], ["info"],
                                  ["monitor", "--rate-hz", "-1"]])
def test_a_usage_error_is_one_line_naming_the_help(argv, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "usage:" not in err
    assert err.startswith(f"fogmon {argv[0]}: error: ") and err.endswith(f" (see fogmon {argv[0]} --help)\n")


def test_no_command_is_one_line_too(capsys):
    with pytest.raises(SystemExit):
        main([])
    assert capsys.readouterr().err == ("fogmon: error: the following arguments are required: COMMAND "
                                       "(see fogmon --help)\n")


def test_a_closed_pipe_is_an_exit_status_not_a_traceback():
    """`fogmon ... | head`: the reader closes its end; the program ends with 141 (what a
    shell shows for SIGPIPE), no traceback on stderr."""
    import os
    import subprocess
    import sys

    from fogmon.cli import BROKEN_PIPE_EXIT

    BUNDLED = os.path.join(os.path.dirname(__file__), "..", "..", "replay_logs", "sim_in_orbit_1hz.csv")
    r, w = os.pipe()
    os.close(r)
    try:
        p = subprocess.run([sys.executable, "-m", "fogmon", "info", str(BUNDLED)], stdout=w,
                           stderr=subprocess.PIPE, text=True, timeout=300)
    finally:
        os.close(w)
    assert p.returncode == BROKEN_PIPE_EXIT and "Traceback" not in p.stderr
