"""Output paths, checked before any analysis starts: a bad path is a one-line FogmonError
at once, not a traceback after minutes of work."""
from __future__ import annotations

import os
from collections.abc import Iterable

from fogmon.errors import FogmonError


def _same(a: str, b: str) -> bool:
    return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)


def check_outputs(outputs: dict[str, str | None], inputs: Iterable[str | None] = ()) -> None:
    """FogmonError naming the output unless every output path (what names it in a
    message, e.g. "`report`" or "`export` kalibr" -> path; None: not asked for) can be
    written as a file: its folder exists and is writable, it is not a folder, and it is
    neither one of the ``inputs`` nor another output. The check leaves nothing behind
    (an existing file is opened for appending, unchanged)."""
    given = [(opt, path) for opt, path in outputs.items() if path]
    in_paths = [p for p in inputs if p]
    for i, (opt, path) in enumerate(given):
        folder = os.path.dirname(os.path.abspath(path))
        if os.path.isdir(path):
            raise FogmonError(f"{opt} {path}: is a folder, give a file name")
        if not os.path.isdir(folder):
            raise FogmonError(f"{opt} {path}: folder {folder} does not exist")
        for other in in_paths:
            if _same(path, other):
                raise FogmonError(f"{opt} {path}: is the input {other}; write to another file")
        for opt2, path2 in given[:i]:
            if os.path.abspath(path) == os.path.abspath(path2):
                raise FogmonError(f"{opt} {path}: also given as {opt2}")
        existed = os.path.exists(path)
        try:
            with open(path, "ab"):
                pass
        except OSError as e:
            raise FogmonError(f"{opt} {path}: cannot write: {e.strerror}") from None
        if not existed:
            os.remove(path)
