"""Rotated outputs (``--rotate-s S``): a long run is written as numbered pieces, each a
complete file of its kind, named by inserting the piece number before the extension:
``samples.csv`` -> ``samples-0001.csv``, ``samples-0002.csv``, ...; ``run.rrd`` ->
``run-0001.rrd``, ... Piece k holds the samples of recording time [(k-1) S, k S) from
the first sample; a piece that received nothing has no file."""
from __future__ import annotations

import os
import re

#: Digits of a piece number (more when a run has more pieces).
PIECE_DIGITS = 4


def piece_path(path: str, piece: int) -> str:
    """``path`` with ``-NNNN`` (the piece number, from 1) before its extension."""
    stem, ext = os.path.splitext(os.fspath(path))
    return f"{stem}-{piece:0{PIECE_DIGITS}d}{ext}"


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
