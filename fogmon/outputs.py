"""Outputs: checked before any work starts, and written so that a failure never leaves
a broken file.

``check_outputs`` is the one check every command runs on what it will write, before
reading anything: a bad output is a one-line FogmonError at once, not a traceback after
minutes of work. An output is refused when

- its folder does not exist (the policy of every command: fogmon creates the files it
  writes and the folders that are outputs themselves, ``batch --out DIR`` and the
  monitor's time-stamped archive folder, never a folder above an output: a typo must
  not scatter folders, ``--rrd /nonexistent/x.rrd`` must not make one at the root),
  it cannot be written there, or it is a folder where a file is asked for;
- it resolves (after symlinks and hard links) to any file an input is read from: the
  input itself, its capture sidecar (``X.json``) and the DBC the sidecar names, every
  file of an archive folder; an output written in numbered pieces (``--rotate-s``:
  ``OUT-0001.rrd``, ...) counts each piece;
- an archive folder would read it as one of its own (a piece name such as
  ``samples-0003.csv`` in a monitor's archive folder), input or not;
- two outputs are the same file.

The check leaves nothing behind (a dangling symlink's target is not created).

``written(path)`` writes a file under a temporary name in the target's folder and
renames it when complete, so ``path`` is either the whole new file or untouched; an
OSError (disk full, quota, I/O error, a file-size limit) becomes a one-line FogmonError
naming the file and the free space (``write_failed``). ``check_space`` refuses work
whose output cannot fit."""
from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import shutil
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

from fogmon.errors import FogmonError
from fogmon.formats.archive import archive_files, archive_of, piece_path


@dataclass(frozen=True)
class Output:
    """One output: ``name`` says how messages name it (a parameter in backticks, such as
    "`report`", or a label); ``pieces``: written as numbered pieces ``OUT-0001.ext``, ...
    (never ``path`` itself); ``folder``: a folder the command writes files into,
    created when ``create`` (its parent must exist), else it must exist."""

    name: str
    path: str
    pieces: bool = False
    folder: bool = False
    create: bool = True


def _outputs(outputs: Mapping[str, str | None] | Iterable[Output]) -> list[Output]:
    if isinstance(outputs, Mapping):
        return [Output(name, path) for name, path in outputs.items() if path]
    return [o for o in outputs if o.path]


def _key(path: str) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _sidecar_dbc(sidecar: str) -> str | None:
    """The DBC a capture sidecar names (a file in its folder), if it names one."""
    try:
        with open(sidecar, encoding="utf-8") as fh:
            name = json.load(fh).get("dbc")
    except (OSError, ValueError, AttributeError):
        return None
    return os.path.join(os.path.dirname(sidecar), name) if isinstance(name, str) and name else None


def input_files(inputs: Iterable[str | None]) -> dict[str, str]:
    """Every existing file or folder the ``inputs`` are read from, by real path, each
    with how a message names it: an input itself, its capture sidecar and the DBC that
    names, an archive folder and every file in it."""
    out: dict[str, str] = {}

    def add(path: str, label: str) -> None:
        out.setdefault(os.path.realpath(path), label)

    for given in inputs:
        if not given or not os.path.exists(given):
            continue
        add(given, given)
        if os.path.isdir(given):
            if archive_files(given):
                for folder, dirs, files in os.walk(given):
                    for f in dirs + files:
                        add(os.path.join(folder, f), f"{os.path.join(folder, f)} (in the archive {given})")
            continue
        side = given + ".json"
        if os.path.isfile(side):
            add(side, f"{side} (the sidecar of {given})")
            dbc = _sidecar_dbc(side)
            if dbc and os.path.isfile(dbc):
                add(dbc, f"{dbc} (the DBC of {given})")
    return out


def _pieces_of(path: str) -> re.Pattern[str]:
    """The names of ``path``'s numbered pieces (fogmon.formats.archive.piece_path)."""
    stem, ext = os.path.splitext(os.path.basename(path))
    return re.compile(rf"{re.escape(stem)}-\d{{4,}}{re.escape(ext)}")


def _real(path: str) -> str:
    return os.path.realpath(path)


def _check_one(o: Output, ins: dict[str, str], in_keys: dict[tuple[int, int], str]) -> None:
    """The checks of one output against the inputs (folders, conflicts, archives)."""
    real = _real(o.path)
    shown = f"{o.path} (a link to {real})" if os.path.islink(o.path) else o.path
    if o.folder:
        if os.path.exists(real) and not os.path.isdir(real):
            raise FogmonError(f"{o.name} {shown}: is a file, give a folder")
        if not os.path.isdir(real) and not o.create:
            raise FogmonError(f"{o.name} {shown}: folder does not exist (fogmon creates no folder above its "
                              f"outputs)")
    elif os.path.isdir(real):
        raise FogmonError(f"{o.name} {shown}: is a folder, give a file name")
    folder = os.path.dirname(real)
    if not os.path.isdir(real) and not os.path.isdir(folder):
        given = os.path.dirname(os.path.abspath(o.path))
        raise FogmonError(f"{o.name} {o.path}: folder {given if folder == _real(given) else folder} does not exist")
    hit = ins.get(real) or in_keys.get(_key(real) or (-1, -1))
    if hit:
        raise FogmonError(f"{o.name} {shown}: is the input {hit}; write to another file")
    if o.pieces:
        pat = _pieces_of(real)
        for p, label in ins.items():
            if os.path.dirname(p) == folder and pat.fullmatch(os.path.basename(p)):
                raise FogmonError(f"{o.name} {o.path}: its pieces ({os.path.basename(piece_path(real, 1))}, ...) "
                                  f"would overwrite the input {label}; write to another file")
    for target in ([piece_path(real, 1)] if o.pieces else [real]):
        arch = archive_of(target)
        if arch is not None and not o.folder:
            raise FogmonError(f"{o.name} {o.path}: the archive {arch} would read {os.path.basename(target)} as one "
                              f"of its pieces; write elsewhere")


def _probe(o: Output) -> None:
    """FogmonError unless the output can be written; leaves nothing behind."""
    real = _real(o.path)
    if o.folder or not os.path.exists(real):
        where = real if os.path.isdir(real) else os.path.dirname(real)
        probe = os.path.join(where, f".fogmon-probe-{os.getpid()}")
        try:
            os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
            os.remove(probe)
        except FileExistsError:
            pass
        except OSError as e:
            raise FogmonError(f"{o.name} {o.path}: cannot write: {e.strerror}") from None
        return
    try:
        with open(real, "ab"):    # an existing file: opened for appending, unchanged
            pass
    except OSError as e:
        raise FogmonError(f"{o.name} {o.path}: cannot write: {e.strerror}") from None


def check_outputs(outputs: Mapping[str, str | None] | Iterable[Output], inputs: Iterable[str | None] = ()) -> None:
    """FogmonError naming the output unless every output (``Output``s, or a mapping
    name -> path of plain files; None: not asked for) can be written without touching
    any of the ``inputs`` (see the module's rules)."""
    given = _outputs(outputs)
    ins = input_files(inputs)
    in_keys = {k: label for p, label in ins.items() if (k := _key(p)) is not None}
    for i, o in enumerate(given):
        _check_one(o, ins, in_keys)
        real = _real(o.path)
        for o2 in given[:i]:
            real2 = _real(o2.path)
            same = real == real2 or (o2.pieces and _pieces_of(real2).fullmatch(os.path.basename(real))
                                     and os.path.dirname(real) == os.path.dirname(real2)) \
                or (o.pieces and _pieces_of(real).fullmatch(os.path.basename(real2))
                    and os.path.dirname(real) == os.path.dirname(real2))
            if same:
                raise FogmonError(f"{o.name} {o.path}: also given as {o2.name}")
        _probe(o)


# -- writing --------------------------------------------------------------------------
def _size(n: float) -> str:
    """Bytes as a short text (decimal units): 0 B, 912 kB, 1.23 GB."""
    for unit, div in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= div:
            return f"{n / div:.3g} {unit}"
    return f"{int(n)} B"


def free_bytes(path: str) -> int | None:
    """Bytes free for this user in the file system holding ``path`` (a file or a
    folder; the nearest existing folder above it), None when unknown."""
    where = os.path.abspath(path)
    while not os.path.isdir(where):
        parent = os.path.dirname(where)
        if parent == where:
            return None
        where = parent
    try:
        return shutil.disk_usage(where).free
    except OSError:
        return None


def space_note(path: str) -> str:
    """"N free in FOLDER" for a message about writing ``path``."""
    free = free_bytes(path)
    folder = os.path.dirname(os.path.abspath(path))
    return f"{_size(free)} free in {folder}" if free is not None else f"free space of {folder} unknown"


def write_failed(name: str, path: str, e: OSError | str) -> FogmonError:
    """The one-line error of a write that failed (disk full, quota, I/O error, file
    size limit): what, where, the free space."""
    # the system's words for the errno (pyarrow wraps them in its own)
    why = e if isinstance(e, str) else os.strerror(e.errno) if e.errno else (e.strerror or str(e))
    if isinstance(e, OSError) and e.errno == errno.EFBIG:
        why += " (a file-size limit: ulimit -f)"
    return FogmonError(f"{name + ' ' if name else ''}{path}: cannot write: {why} ({space_note(path)})")


def temp_path(path: str) -> str:
    """A temporary name for writing ``path``: in the folder of its real path (symlinks
    followed), hidden, with the same extension (libraries pick formats by it)."""
    real = _real(path)
    folder, base = os.path.split(real)
    stem, ext = os.path.splitext(base)
    return os.path.join(folder, f".{stem}.{os.getpid()}.tmp{ext}")


@contextlib.contextmanager
def written(path: str, name: str = "", errors: tuple[type[BaseException], ...] = (OSError,)) -> Iterator[str]:
    """``with written(path) as tmp: write(tmp)``: the file is written as ``tmp`` and
    renamed to ``path`` (its real path: a symlink's target) when the block ends, so
    ``path`` is never half written; on any failure ``tmp`` is removed and ``errors``
    (OSError; a caller adds e.g. Rerun's RuntimeError) become ``write_failed``. A
    writer that writes nothing leaves ``path`` as it was. A special file (/dev/null, a
    pipe) is written directly."""
    real = _real(path)
    if os.path.exists(real) and not os.path.isfile(real):
        try:
            yield real
        except errors as e:   # type: ignore[misc]
            raise _failed(name, path, e) from None
        return
    tmp = temp_path(path)
    try:
        yield tmp
        if os.path.lexists(tmp):
            os.replace(tmp, real)
    except BaseException as e:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        if isinstance(e, errors):
            raise _failed(name, path, e) from None
        raise


def _failed(name: str, path: str, e: BaseException) -> FogmonError:
    if isinstance(e, OSError):
        return write_failed(name, path, e)
    return write_failed(name, path, str(e).splitlines()[0] if str(e) else type(e).__name__)


def check_space(name: str, path: str, n_bytes: float, what: str) -> None:
    """FogmonError when ``n_bytes`` (``what`` they are, e.g. "3.6e6 rows of 23.3 bytes")
    cannot fit in the free space where ``path`` is written."""
    free = free_bytes(path)
    if free is not None and n_bytes > free:
        raise FogmonError(f"{name} {path}: {what} take {_size(n_bytes)}, and {space_note(path)}")
