"""Library messages name parameters in backticks (fogmon.errors): an API user reads the
parameter's name, `fogmon` prints the command's flag (fogmon.cli.render) - the same text
the command printed when the library held the flags itself."""
from __future__ import annotations

import ast
import pickle
import re
import warnings
from pathlib import Path

import pytest

import fogmon
from fogmon.cli import ALIASES, COMMANDS, NO_FLAG, _options, command_flags, main, render
from fogmon.errors import NAME, FogmonError, FogmonWarning, render_names

ROOT = Path(fogmon.__file__).resolve().parent


def test_a_name_reads_plainly_and_renders_as_a_flag():
    e = FogmonError("`sample_rate_hz` must be > 0, got 0 (``not_a_name``, `two words`)")
    assert str(e) == "sample_rate_hz must be > 0, got 0 (``not_a_name``, `two words`)"
    assert e.render({"sample_rate_hz": "--rate-hz"}) == "--rate-hz must be > 0, got 0 (``not_a_name``, `two words`)"
    assert e.message == "`sample_rate_hz` must be > 0, got 0 (``not_a_name``, `two words`)"
    assert pickle.loads(pickle.dumps(e)).message == e.message        # a Dask task's error keeps its names
    with pytest.raises(FogmonError, match=r"^sample_rate_hz must"):
        raise e
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        warnings.warn("`taus` 1000: left out", FogmonWarning, stacklevel=1)
    assert str(w[0].message) == "taus 1000: left out"
    assert w[0].message.render({"taus": "--taus"}) == "--taus 1000: left out"


def test_the_command_renders_its_own_flags_aliases_and_other_commands():
    assert render("`sample_rate_hz` and `n_samples`", "fit") == "--rate-hz and --record-s"
    assert render("`thermal` and `rrd_path` and `n_boot`", "replay") == "--thermal-cal and --rrd and `n_boot`"
    assert render(FogmonError("run fogmon thermal `out_model`; start `rerun`"), "replay") == \
        "run fogmon thermal --out-model; start `rerun`"       # another command's option; no option: as written


def _message_names() -> dict[str, list[str]]:
    """Every backticked name in a string of library code (outside fogmon/cli) that is not
    a docstring -> where it is (file:line)."""
    out: dict[str, list[str]] = {}
    for path in sorted(ROOT.rglob("*.py")):
        if path.relative_to(ROOT).parts[0] == "cli":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        docs = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Expr)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
                for name in NAME.findall(node.value):
                    out.setdefault(name, []).append(f"{path.relative_to(ROOT.parent)}:{node.lineno}")
    return out


def test_every_name_a_library_message_gives_is_an_option_of_a_command():
    """Each backticked name maps to a flag of some command (its dest, or an alias of one),
    or is in fogmon.cli.NO_FLAG (shown as written); a name several commands have is the
    same flag in each, so the name says one thing whichever command prints it."""
    tables = {c: _options(c) for c in COMMANDS}
    flags: dict[str, set[str]] = {}
    for table in tables.values():
        for dest, flag in table.items():
            flags.setdefault(dest, set()).add(flag)
    assert {d: f for d, f in flags.items() if len(f) > 1} == {}
    assert all(dest in flags for dest in ALIASES.values()), ALIASES
    names = _message_names()
    assert len(names) >= 10        # the scan sees the messages
    unknown = {n: where for n, where in names.items() if n not in flags and n not in ALIASES and n not in NO_FLAG}
    assert unknown == {}


def test_a_flag_in_a_library_message_is_a_name():
    """No literal ``--flag`` in a message string of the modules converted so far (the
    others convert theirs with their restructuring, issue 27)."""
    converted = ["errors.py", "export.py", "fleet", "sim", "methods", "modelcheck", "davar", "block.py",
                 "__init__.py", "outputs.py", "sinks/base.py", "sinks/console.py", "units.py", "motion.py",
                 "phases.py", "pipeline", "formats", "sources", "sinks/archive.py", "sinks/parquet_pieces.py",
                 "stopping.py", "startup.py", "sinks/rerun/server.py", "explain/mismatch.py", "explain/axes.py"]
    flag = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
    bad = []
    for part in converted:
        for path in [ROOT / part] if part.endswith(".py") else sorted((ROOT / part).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            docs = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Expr)}
            bad += [(str(path.relative_to(ROOT.parent)), flag.findall(n.value)) for n in ast.walk(tree)
                    if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs
                    and flag.search(n.value)]
    # events' texts, which the Rerun sink shows as is: an error counter's, a device's (dis)connection;
    # the rerun program's own command line (its options, not fogmon's)
    assert sorted(bad) == [("fogmon/errors.py", ["--max-rate-dph"]),
                           ("fogmon/sinks/rerun/server.py", ["--bind"]),
                           ("fogmon/sinks/rerun/server.py", ["--port"]),
                           ("fogmon/sinks/rerun/server.py", ["--serve-grpc"]),
                           ("fogmon/sources/devices/can_bus.py", ["--can"]),
                           ("fogmon/sources/devices/can_bus.py", ["--interface"]),
                           ("fogmon/sources/devices/serial_port.py", ["--serial"])]


def test_the_console_summary_names_flags_from_the_command_and_parameters_from_the_api():
    from fogmon.sinks.base import Summary
    from fogmon.sinks.console import format_summary

    s = Summary("KVH", 100.0, 655.36, 81.92, n_samples=12_000, t_first_s=0.0, t_last_s=119.99,
                analysed="rate_dph - 3600 x rot_dps, thermal")
    api, cli = format_summary(s), format_summary(s, command_flags("monitor"))
    assert "use window_s 20.48" in api and "(raw_rate for rate_dph itself)" in api and "the thermal drift" in api
    assert "use --window-s 20.48" in cli and "(--raw-rate for rate_dph itself)" in cli
    assert "the --thermal-cal drift" in cli
    assert render_names(cli) == cli and "`" not in api + cli


def test_library_messages_reach_the_user_with_the_commands_flags(tmp_path, capsys):
    curve = tmp_path / "c.csv"
    curve.write_text("tau_s,adev_dph\n0.015,1\n0.03,0.7\n")
    assert main(["fit", str(curve)]) == 0
    out = capsys.readouterr().out
    assert "  assumed: sample rate 66.6667 Hz (1 / the first tau; --rate-hz sets it)\n" in out
    assert "(4 x the largest tau; an n_terms column or --record-s sets it)\n" in out
    curve.write_text("tau_s,adev_dph\n0.01,1\n0.015,0.7\n")
    assert main(["fit", str(curve)]) == 2
    assert capsys.readouterr().err == (f"fogmon fit: error: {curve}: line 3, column tau_s: tau_s 0.015 s is not a "
                                       "whole multiple of the "
                                       "sample period 0.01 s (1.5 periods, more than 1e-05 from a whole number; "
                                       "give the record's sample rate with --rate-hz)\n")
