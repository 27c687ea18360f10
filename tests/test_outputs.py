"""Issue 31.1: outputs never touch inputs. Every command's outputs are checked before any
work (fogmon.cli.output_options.check_command_outputs): an output that is an input
(the same file, through a symlink, as a numbered piece of a rotated output), a piece
name in an archive folder, or in a folder that does not exist is a one-line error (exit
2), and nothing is written or created: the input is unchanged, no folder is made, a
dangling symlink's target is not created."""
from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO

from fogmon.cli import COMMANDS, build_parser, main
from fogmon.cli.output_options import command_outputs
from fogmon.formats.replay_log import write_replay_log

DATA = REPO / "fogmon" / "data"

#: command -> (argv writing ``out`` from the inputs ``i``, the option naming ``out``,
#: the input ``out`` is made the same file as); ``rotate``: its output takes --rotate-s
COMMAND_CASES = {
    "replay": (lambda i, out: ["replay", i["rec"], "--rrd", out, "--no-progress"], "--rrd", "rec"),
    "monitor": (lambda i, out: ["monitor", "--serial", i["port"], "--protocol", "kvh-a", "--model", i["model"],
                                "--archive", i["runs"], "--rrd", out, "--no-progress"], "--rrd", "model"),
    "sim": (lambda i, out: ["sim", "--model", i["model"], "--like", i["rec"], "--out", out], "--out", "rec"),
    "explain": (lambda i, out: ["explain", i["rec"], "--report", out, "--quiet"], "--report", "rec"),
    "fit": (lambda i, out: ["fit", i["curve"], "--export", "kalibr", out], "--export kalibr", "curve"),
    "convert": (lambda i, out: ["convert", i["rec"], out], "OUT", "rec"),
    "batch": (lambda i, out: ["batch", i["rec"], "--out", i["fleet"], "--report", out, "--no-progress"],
              "--report", "rec"),
    "thermal": (lambda i, out: ["thermal", i["rec"], "--out-corrected", out], "--out-corrected", "rec"),
}
#: commands that write no file (only print): nothing to check, with arguments they parse
NO_OUTPUTS = {"inorbit": ["x.csv"], "updown": ["--up", "u.csv", "--down", "d.csv", "--lat-deg", "45"],
              "info": ["x.csv"]}
ROTATING = ("replay", "monitor")


def _digest(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (symlinks as their target name) -> its content's hash."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_symlink():
            out[str(p)] = "-> " + os.readlink(p)
        elif p.is_file():
            out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
        else:
            out[str(p)] = "folder"
    return out


@pytest.fixture
def inputs(tmp_path) -> dict[str, str]:
    n = 2000
    t = np.arange(n) / 10.0
    rec = tmp_path / "rec.csv"
    write_replay_log(rec, t, np.random.default_rng(1).standard_normal(n), {"temp_c": 20 + t / 100},
                     {"sample_rate_hz": 10})
    model = tmp_path / "model.toml"
    shutil.copy(DATA / "example_model.toml", model)
    curve = tmp_path / "curve.csv"
    curve.write_text("tau_s,adev_dph\n" + "".join(f"{2.0 ** k!r},{1.0 / 2 ** (k / 2)!r}\n" for k in range(8)))
    arch = tmp_path / "arch"                       # an archive folder (not an input of the commands)
    arch.mkdir()
    write_replay_log(arch / "samples-0001.csv", t, np.zeros(n), meta={"sample_rate_hz": 10, "piece": 1})
    runs = tmp_path / "runs"
    runs.mkdir()
    return {"rec": str(rec), "model": str(model), "curve": str(curve), "arch": str(arch), "runs": str(runs),
            "fleet": str(tmp_path / "fleet"), "port": str(tmp_path / "no-such-port")}


def _refused(argv: list[str], capsys, message: str, tmp_path: Path) -> None:
    before = _digest(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert _digest(tmp_path) == before                       # nothing written, created or changed


@pytest.mark.parametrize("command", COMMAND_CASES)
def test_an_output_that_is_an_input_is_refused(command, inputs, tmp_path, capsys):
    argv, flag, same = COMMAND_CASES[command]
    _refused(argv(inputs, inputs[same]), capsys, f"{flag} {inputs[same]}: is the input {inputs[same]}; write to "
                                                 f"another file", tmp_path)


@pytest.mark.parametrize("command", COMMAND_CASES)
def test_an_output_linked_to_an_input_is_refused(command, inputs, tmp_path, capsys):
    argv, flag, same = COMMAND_CASES[command]
    link = tmp_path / "link.out"
    link.symlink_to(inputs[same])
    _refused(argv(inputs, str(link)), capsys, f"{flag} {link} (a link to {inputs[same]}): is the input "
                                              f"{inputs[same]}; write to another file", tmp_path)


@pytest.mark.parametrize("command", ROTATING)
def test_pieces_of_a_rotated_output_that_would_overwrite_an_input_are_refused(command, inputs, tmp_path, capsys):
    argv, flag, same = COMMAND_CASES[command]
    piece = Path(inputs[same]).with_name(Path(inputs[same]).stem + "-0001" + Path(inputs[same]).suffix)
    os.replace(inputs[same], piece)                            # the input is named like a piece of the output
    ins = {**inputs, same: str(piece)}
    _refused([*argv(ins, inputs[same]), "--rotate-s", "60"], capsys,
             f"{flag} {inputs[same]}: its pieces ({piece.name}, ...) would overwrite the input {piece}", tmp_path)


@pytest.mark.parametrize("command", COMMAND_CASES)
@pytest.mark.parametrize("name", ["samples-0001.csv", "samples-0002.csv", "raw-0003.bin"])
def test_an_output_named_as_an_archive_piece_is_refused(command, name, inputs, tmp_path, capsys):
    argv, flag, _ = COMMAND_CASES[command]
    out = os.path.join(inputs["arch"], name)
    _refused(argv(inputs, out), capsys, f"{flag} {out}: the archive {inputs['arch']} would read {name} as one of "
                                        f"its pieces; write elsewhere", tmp_path)


@pytest.mark.parametrize("command", COMMAND_CASES)
def test_an_output_in_a_missing_folder_is_refused_and_no_folder_made(command, inputs, tmp_path, capsys):
    argv, flag, _ = COMMAND_CASES[command]
    out = tmp_path / "no" / "such" / "out.csv"
    _refused(argv(inputs, str(out)), capsys, f"{flag} {out}: folder {out.parent} does not exist", tmp_path)


@pytest.mark.parametrize("command", COMMAND_CASES)
def test_a_dangling_link_as_output_creates_nothing_when_the_command_fails(command, inputs, tmp_path, capsys):
    argv, _, same = COMMAND_CASES[command]
    link, target = tmp_path / "dangling.csv", tmp_path / "target.csv"
    link.symlink_to(target)
    missing = str(tmp_path / "missing" if command != "monitor" else inputs["port"])
    assert main(argv({**inputs, same: missing, "rec": missing}, str(link))) != 0
    assert "Traceback" not in capsys.readouterr().err
    assert not target.exists() and link.is_symlink()


def test_the_archive_folder_must_exist(inputs, tmp_path, capsys):
    argv, _, _ = COMMAND_CASES["monitor"]
    runs = tmp_path / "no-runs"
    _refused(argv({**inputs, "runs": str(runs)}, str(tmp_path / "live.rrd")), capsys,
             f"--archive {runs}: folder does not exist", tmp_path)
    _refused(argv({**inputs, "runs": inputs["arch"]}, str(tmp_path / "live.rrd")), capsys,
             f"--archive {inputs['arch']}: is an archive folder; give the folder to make the run's archive folder in",
             tmp_path)


def test_two_outputs_that_are_the_same_file_are_refused(inputs, tmp_path, capsys):
    out = str(tmp_path / "x.rrd")
    _refused(["replay", inputs["rec"], "--rrd", out, "--export", "kalibr", out], capsys,
             f"--export kalibr {out}: also given as --rrd", tmp_path)


def test_rrd_at_a_missing_root_folder_makes_no_folder(inputs, capsys):
    assert main(["replay", inputs["rec"], "--rrd", "/fogmon-no-such-folder/x.rrd"]) == 2
    assert "--rrd /fogmon-no-such-folder/x.rrd: folder /fogmon-no-such-folder does not exist" in capsys.readouterr().err
    assert not os.path.exists("/fogmon-no-such-folder")


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_is_covered(command):
    """A command either has output cases above or writes nothing at all."""
    if command in NO_OUTPUTS:
        p = build_parser([command])
        args = p.parse_args([command, *NO_OUTPUTS[command]])
        assert command_outputs(args) == []
        written = {"rrd", "out", "report", "export", "out_model", "out_corrected", "output", "archive"}
        assert not written & set(vars(args))
    else:
        assert command in COMMAND_CASES
