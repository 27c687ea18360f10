"""CAN logs python-can reads (.asc .blf .trc .csv .log .mf4), decoded with the DBC
codec (fogmon.sources.codecs.can) and put on the sample grid; the pieces of an
archive's ASC log (frames-NNNN.asc) as one stream."""
from __future__ import annotations

import functools
import os
from collections.abc import Iterator

import can

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.formats.capture import CAN_DECODER_FIELDS
from fogmon.sources.codecs.can import CanDecoder, load_dbc
from fogmon.sources.files.capture import read_capture_sidecar
from fogmon.sources.frames import Frames
from fogmon.sources.grid import ErrorEvents, GridAssembler
from fogmon.sources.options import SourceOptions


def _push_segments(grid: GridAssembler, segs, events) -> Block:
    blocks = []
    for i, (brk, frames) in enumerate(segs):
        if brk is not None:
            grid.mark_break(brk)
        blocks.append(grid.push(frames, events if i == 0 else ()))
    if not blocks:
        return grid.push(Frames.empty(grid.aux_names, grid.axes), events)
    return Block.concat(blocks)


class CanLogSource:
    """A CAN log python-can reads (.asc .blf .trc .csv .log .mf4) decoded with a DBC; or
    the pieces of one ASC log (an archive's frames-NNNN.asc), read in order with their
    absolute timestamps so that one decoder sees one continuous stream of frames."""

    CHUNK = 4096

    def __init__(self, path: str | list[str], db, **decoder_options) -> None:
        self.paths = [path] if isinstance(path, str) else list(path)
        self.path = self.paths[0]
        self._db, self._options = db, decoder_options
        self.decoder = CanDecoder(db, **decoder_options)
        self.sample_rate_hz = self.decoder.sample_rate_hz
        self.aux_names = self.decoder.aux_names
        self.axes = self.decoder.axes
        self.grid = GridAssembler(self.sample_rate_hz, self.decoder.seq_modulus, self.aux_names, axes=self.axes)
        what = os.path.basename(self.path) + (
            f" .. {os.path.basename(self.paths[-1])} ({len(self.paths)} pieces)" if len(self.paths) > 1 else "")
        self.name = f"CAN log {what}: {self.decoder.describe()}"
        self._closed = False

    @property
    def counters(self) -> dict[str, int]:
        return {**self.decoder.counters, **self.grid.counters}

    @functools.cached_property
    def n_samples(self) -> int:
        """Samples on the grid, from a counting pass over the log (pipelines size their
        default window with it)."""
        return sum(len(b) for b in CanLogSource(self.paths, self._db, **self._options).blocks())

    def blocks(self) -> Iterator[Block]:
        errors = ErrorEvents(self.decoder.counters)
        # pieces: absolute ASC timestamps, so the gap between two pieces is measured
        kwargs = {"relative_timestamp": False} if len(self.paths) > 1 else {}
        for path in self.paths:
            try:
                reader = can.LogReader(path, **kwargs)
            except Exception as e:  # unknown suffix, unreadable header, ...
                raise FogmonError(f"{path}: cannot read as a CAN log: {e}") from None
            it = iter(reader)
            try:
                while not self._closed:
                    chunk = []
                    try:
                        for m in it:
                            chunk.append(m)
                            if len(chunk) >= self.CHUNK:
                                break
                    except Exception as e:  # a corrupt log: say where, do not trace back
                        raise FogmonError(f"{path}: unreadable CAN log after "
                                          f"{self.decoder.counters['frames_ok']} frames: {e}") from None
                    if not chunk:
                        break
                    segs = self.decoder.feed(chunk)
                    b = _push_segments(self.grid, segs, errors.poll(self.grid.t_next_s))
                    if len(b):
                        yield b
            finally:
                reader.stop()

    def close(self) -> None:
        self._closed = True


def open_can_log(path: str | list[str], dbc: str | None, options: dict, sidecar: dict | None) -> CanLogSource:
    """A CAN log source (or the pieces of one ASC log, in order); decoder options from the
    (first piece's) sidecar, overridden by ``options``; the DBC from ``dbc`` or the
    sidecar's copy, which fogmon.formats.capture.read_sidecar has confined to the sidecar's folder."""
    first = path if isinstance(path, str) else path[0]
    opts = {}
    if sidecar:
        opts.update({k: sidecar[k] for k in CAN_DECODER_FIELDS if sidecar.get(k) is not None})
        if not dbc and sidecar.get("dbc"):
            dbc = os.path.join(os.path.dirname(os.path.abspath(first)), sidecar["dbc"])
    opts.update({k: v for k, v in options.items() if v is not None})
    if not dbc:
        raise FogmonError(f"{first}: a CAN log needs `dbc` F describing the gyro's frames")
    return CanLogSource(path, load_dbc(dbc), **opts)


def open_source(path: str, opts: SourceOptions) -> CanLogSource:
    """The CAN log ``path`` with the DBC and decoder options ``opts`` gives, else its
    sidecar's."""
    return open_can_log(path, opts.dbc, opts.can_options(), read_capture_sidecar(path))
