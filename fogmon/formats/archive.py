"""The archive folder layout (``fogmon monitor --archive``; docs/sources.md,
docs/monitor.md): the folder's name, the names of the files in it, their numbering in
pieces, and finding them. The one place that knows it: the writers (fogmon.sinks.archive,
fogmon.sinks.parquet_pieces) and the readers (fogmon.sources.files.archive, fogmon.fleet)
use it.

Rotated outputs (``rotate_s`` = S s): a long run is written as numbered pieces, each a
complete file of its kind, named by inserting the piece number before the extension:
``samples.csv`` -> ``samples-0001.csv``, ``samples-0002.csv``, ...; ``run.rrd`` ->
``run-0001.rrd``, ... Piece k holds the samples of recording time [(k-1) S, k S) from
the first sample; a piece that received nothing has no file. A Parquet piece being
written is a folder ``samples-NNNN.parquet.parts`` of row-group files
``part-MMMMMM.parquet`` until it is joined into ``samples-NNNN.parquet``."""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from datetime import UTC, datetime

#: Digits of a piece number (more when a run has more pieces).
PIECE_DIGITS = 4
#: the decoded samples as replay-log CSV pieces (fogmon.formats.replay_log)
REPLAY_LOG = "samples.csv"
#: the decoded samples as Parquet pieces (fogmon.formats.parquet_log)
PARQUET_LOG = "samples.parquet"
#: the folder of a Parquet piece's row-group parts while it is written
PARTS_SUFFIX = ".parts"
#: a serial gyro's raw capture pieces (fogmon.formats.capture)
SERIAL_CAPTURE = "raw.bin"
#: a CAN gyro's raw capture pieces (python-can ASC logs, fogmon.formats.capture)
CAN_CAPTURE = "frames.asc"
#: the lock file of an archive being written (its writer's pid; fogmon.sinks.archive)
LOCK = ".fogmon-archive.lock"
#: the prefix of the folder each `fogmon monitor` run makes (``default_archive_dir``)
FOLDER_PREFIX = "fogmon-archive-"

_PIECE = rf"(-\d{{{PIECE_DIGITS},}})?"
#: names an archive folder's readers take as part of the archive: the pieces (numbered or
#: not) with their sidecars and Parquet parts folders, the DBC copy and the lock
_ARCHIVE_NAMES = re.compile(rf"(samples{_PIECE}\.csv|samples{_PIECE}\.parquet({re.escape(PARTS_SUFFIX)})?|"
                            rf"raw{_PIECE}\.bin(\.json)?|frames{_PIECE}\.asc(\.json)?|.*\.dbc|{re.escape(LOCK)})")


def default_archive_dir(base: str = ".") -> str:
    """A new time-stamped folder name under ``base``: ``fogmon-archive-YYYYmmddTHHMMSSZ``
    (``-2``, ``-3``, ... added when a folder of that name exists: two runs started in
    the same second)."""
    path = os.path.join(base, datetime.now(UTC).strftime(f"{FOLDER_PREFIX}%Y%m%dT%H%M%SZ"))
    n, out = 1, path
    while os.path.lexists(out):
        n += 1
        out = f"{path}-{n}"
    return out


def is_archive_name(name: str) -> bool:
    """True when a file or folder named ``name`` in an archive folder is read as part of
    the archive (a piece, its sidecar or Parquet parts, the DBC copy, the lock)."""
    return bool(_ARCHIVE_NAMES.fullmatch(name))


def archive_of(path: str) -> str | None:
    """The archive folder that would read a file at ``path`` as one of its own (a piece
    name in an archive folder, or anything in a piece's parts folder), else None."""
    folder, name = os.path.split(os.path.abspath(path))
    if folder.endswith(PARTS_SUFFIX) and archive_files(os.path.dirname(folder)):
        return os.path.dirname(folder)
    return folder if is_archive_name(name) and archive_files(folder) else None


def piece_path(path: str, piece: int) -> str:
    """``path`` with ``-NNNN`` (the piece number, from 1) before its extension."""
    stem, ext = os.path.splitext(os.fspath(path))
    return f"{stem}-{piece:0{PIECE_DIGITS}d}{ext}"


def part_name(part: int) -> str:
    """The file name of row-group part ``part`` (from 1) of a Parquet piece being written."""
    return f"part-{part:06d}.parquet"


def find_pieces(directory: str, name: str) -> list[str]:
    """The pieces of ``name`` (such as ``samples.csv``) in ``directory``, in piece order;
    an unnumbered ``name`` (an archive written without rotation) is the only piece."""
    stem, ext = os.path.splitext(name)
    pattern = re.compile(rf"{re.escape(stem)}-(\d{{{PIECE_DIGITS},}}){re.escape(ext)}")
    try:
        entries = os.listdir(directory)
    except OSError:
        return []
    numbered = sorted((int(m.group(1)), e) for e in entries if (m := pattern.fullmatch(e)))
    if numbered:
        return [os.path.join(directory, e) for _, e in numbered]
    return [os.path.join(directory, name)] if name in entries else []


def piece_files(directory: str) -> list[str]:
    """The Parquet sample files of an archive folder in recording order: per piece its
    joined file, or (a piece whose run was killed) its row-group parts."""
    try:
        entries = set(os.listdir(directory))
    except OSError:
        return []
    stem, ext = os.path.splitext(PARQUET_LOG)
    pat = re.compile(rf"{re.escape(stem)}-(\d{{{PIECE_DIGITS},}}){re.escape(ext)}({re.escape(PARTS_SUFFIX)})?")
    pieces = sorted({int(m.group(1)) for e in entries if (m := pat.fullmatch(e))})
    out: list[str] = []
    for k in pieces:
        name = piece_path(PARQUET_LOG, k)
        if name in entries:
            out.append(os.path.join(directory, name))
            continue
        parts = os.path.join(directory, name + PARTS_SUFFIX)
        out += [os.path.join(parts, p) for p in sorted(os.listdir(parts)) if p.endswith(".parquet")]
    return out


@dataclass(frozen=True)
class ArchiveFiles:
    """What an archive folder holds, each in piece order: ``logs`` the replay-log pieces
    (CSV, or else Parquet files), ``serial`` and ``frames`` the raw capture pieces of a
    serial or a CAN gyro. False when it holds none of them (not an archive)."""

    logs: list[str] = field(default_factory=list)
    serial: list[str] = field(default_factory=list)
    frames: list[str] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.logs or self.serial or self.frames)


def archive_files(directory: str) -> ArchiveFiles:
    """The pieces in archive folder ``directory`` (``ArchiveFiles``)."""
    return ArchiveFiles(find_pieces(directory, REPLAY_LOG) or piece_files(directory),
                        find_pieces(directory, SERIAL_CAPTURE), find_pieces(directory, CAN_CAPTURE))
