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
