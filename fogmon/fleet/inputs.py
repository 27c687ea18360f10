"""The recordings named by `fogmon batch INPUTS...`: files, folders and globs, expanded
and checked for existence before any task starts."""
from __future__ import annotations

import glob
import os
from collections.abc import Sequence

from fogmon.errors import FogmonError

#: file endings read as recordings when a folder is walked (a raw serial capture only
#: with its .json sidecar; CAN logs need a DBC (``dbc``) or a sidecar)
RECORDING_SUFFIXES = (".csv", ".parquet", ".asc", ".blf", ".trc", ".log", ".mf4")


def is_archive(folder: str) -> bool:
    """A `fogmon monitor` archive folder (one recording of several pieces)."""
    from fogmon.formats.archive import archive_files

    return bool(archive_files(folder))


def _walk(folder: str) -> list[str]:
    """Recordings in ``folder``: an archive folder is one; otherwise its recording files
    and (recursively) sub-folders, in name order."""
    if is_archive(folder):
        return [folder]
    out: list[str] = []
    for name in sorted(os.listdir(folder)):
        p = os.path.join(folder, name)
        if os.path.isdir(p):
            out += _walk(p)
        elif name.lower().endswith(RECORDING_SUFFIXES) or os.path.exists(p + ".json") and not name.endswith(".json"):
            out.append(p)
    return out


def input_folders(inputs: Sequence[str]) -> list[str]:
    """The folders among ``inputs`` (given, or matched by a glob): those searched for
    recordings (or read as one archive)."""
    out: list[str] = []
    for arg in inputs:
        paths = sorted(glob.glob(arg, recursive=True)) if any(c in arg for c in "*?[") else [arg]
        out += [p for p in paths if os.path.isdir(p)]
    return out


def check_outside_inputs(outputs: Sequence[tuple[str, str | None, bool]], inputs: Sequence[str]) -> None:
    """FogmonError naming the output unless each output (``outputs``: (name, path,
    whether a folder) triples, path None: not asked for) lies outside every input
    folder: a later batch over that folder would search it and read the tables and the
    report as recordings (and fail on them)."""
    folders = [(f, os.path.realpath(f)) for f in input_folders(inputs)]
    for name, path, is_folder in outputs:
        if path is None:
            continue
        real = os.path.realpath(path if is_folder else os.path.dirname(os.path.abspath(path)))
        for folder, real_folder in folders:
            if real == real_folder or real.startswith(real_folder.rstrip(os.sep) + os.sep):
                where = "is" if is_folder and real == real_folder else "is inside" if is_folder else "is in"
                raise FogmonError(f"{name} {path}: {where} the input folder {folder}, where a later batch over it "
                                  f"would read what is written as recordings; give a place outside it")


def expand_inputs(inputs: Sequence[str]) -> list[str]:
    """The recordings, in order and each once: a glob gives its matches, a folder its
    recordings (``_walk``), a file itself. FogmonError naming the input when one gives
    nothing."""
    out: list[str] = []
    seen: set[str] = set()
    for arg in inputs:
        if any(c in arg for c in "*?["):
            paths = sorted(glob.glob(arg, recursive=True))
            if not paths:
                raise FogmonError(f"{arg}: no file matches")
        elif not os.path.exists(arg):
            raise FogmonError(f"{arg}: no such file or folder")
        else:
            paths = [arg]
        found = []
        for p in paths:
            found += _walk(p) if os.path.isdir(p) else [p]
        if not found:
            raise FogmonError(f"{arg}: holds no recording (replay log, Parquet log, raw capture with its .json "
                              f"sidecar, CAN log, archive folder)")
        for p in found:
            key = os.path.realpath(p)
            if key not in seen:
                seen.add(key)
                out.append(p)
    return out
