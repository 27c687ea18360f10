"""A raw serial capture replayed: the bytes a device sent (an archive's raw-NNNN.bin
pieces, or any file of them), decoded again with its protocol into the same blocks the
live source yielded, as fast as they can (the pipeline paces: ``realtime``).

A raw capture ``X`` may have a sidecar ``X.json`` (fogmon.formats.capture, written by the
archive) naming the protocol and decoder options and the outages seen while recording
(``"breaks": [{"offset": byte offset, "missing_est": samples, "elapsed_s": s}, ...]``) and the gaps its
clock placed (``{"offset", "frame", "missing", "rule", "wraps"}``: fogmon.sources.grid.Placed), so that
replaying it gives exactly the samples the live monitor saw."""
from __future__ import annotations

import functools
import os
from collections.abc import Iterator, Sequence

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.formats.capture import DECODER_FIELDS, SIDECAR_SUFFIX, read_sidecar
from fogmon.sources.base import OfflineSource
from fogmon.sources.codecs.protocols import SIDECAR_CHOICES, codec_from_options
from fogmon.sources.grid import ErrorEvents, GridAssembler, Placed
from fogmon.sources.options import SourceOptions


def read_capture_sidecar(path: str) -> dict | None:
    """The sidecar of capture ``path`` (fogmon.formats.capture.read_sidecar), its decoder
    options checked against the protocol table; None when there is none."""
    return read_sidecar(path, SIDECAR_CHOICES)


class RawCaptureSource(OfflineSource):
    """Bytes a serial device sent, decoded again. ``path`` is one capture file or the
    pieces of one (an archive's raw-NNNN.bin), read in order as one byte stream, so the
    decoder's state (a frame split across two pieces, the sequence counter) carries
    across. ``options`` are the decoder options (``protocol``, ``sample_rate_hz``, ``kvh_rot``,
    ``kvh_units``, ``kvh_accel``, ``axis``, ``columns``; ``axes`` the codec's); ``breaks``
    the outages [(byte offset in the stream, estimated samples lost)] and the gaps placed by
    the live run's clock [(byte offset, samples, fogmon.sources.grid.Placed)]. Counters: the
    decoder's and the grid's (see GridAssembler)."""

    CHUNK = 1 << 16

    def __init__(self, path: str | Sequence[str], options: dict, breaks=()) -> None:
        self.paths = [path] if isinstance(path, str) else list(path)
        for p in self.paths:
            if not os.path.isfile(p):
                raise FogmonError(f"{p}: no such file")
        self._options = dict(options)
        self.codec = codec_from_options(options)
        self.sample_rate_hz = self.codec.sample_rate_hz
        self.axes: tuple[str, ...] = self.codec.axes
        self.grid = GridAssembler(self.sample_rate_hz, self.codec.seq_modulus, self.codec.aux_names, axes=self.axes)
        what = os.path.basename(self.paths[0]) + (
            f" .. {os.path.basename(self.paths[-1])} ({len(self.paths)} pieces)" if len(self.paths) > 1 else "")
        self.name = f"raw capture {what}: {self.codec.describe()}"
        self._breaks = sorted(((int(b[0]), float(b[1]), *b[2:3]) for b in breaks), key=lambda b: b[0])
        self._closed = False

    @property
    def counters(self) -> dict[str, int]:
        return {**self.codec.counters, **self.grid.counters}

    @functools.cached_property
    def n_samples(self) -> int:
        """Samples on the grid, from a counting pass over the file(s) (pipelines size their
        default window with it)."""
        return sum(len(b) for b in RawCaptureSource(self.paths, self._options, self._breaks).blocks())

    def blocks(self) -> Iterator[Block]:
        pos = 0
        breaks = list(self._breaks)
        errors = ErrorEvents(self.codec.counters)
        for path in self.paths:
            try:
                fh = open(path, "rb")  # noqa: SIM115 (closed by the with below; only opening errors are caught)
            except OSError as e:
                raise FogmonError(f"{path}: cannot read: {e.strerror}") from None
            with fh:
                while not self._closed:
                    end = pos + self.CHUNK
                    if breaks and breaks[0][0] <= end:
                        end = breaks[0][0]
                    data = fh.read(end - pos)
                    at_break = bool(breaks) and pos + len(data) == breaks[0][0]
                    if not data and not at_break:
                        break
                    pos += len(data)
                    frames = self.codec.feed(data)
                    if len(frames):
                        yield self.grid.push(frames, errors.poll(self.grid.t_next_s))
                    if at_break:
                        brk = breaks.pop(0)
                        try:
                            if len(brk) > 2:
                                self.grid.place(brk[2])
                            else:
                                self.grid.mark_break(brk[1])
                        except FogmonError as e:     # (a sidecar's number beyond any gap)
                            raise FogmonError(f"{path}{SIDECAR_SUFFIX}: field breaks: {e}") from None

    def close(self) -> None:
        self._closed = True


def open_raw_capture(path: str | Sequence[str], overrides: dict | None = None) -> RawCaptureSource:
    """A raw capture (or the pieces of one, in order) with the decoder options of its
    sidecar(s), overridden by ``overrides`` (the command line); without a sidecar
    ``overrides['protocol']`` is required. Pieces must agree on the decoder options;
    their outages are placed in the joined byte stream."""
    paths = [path] if isinstance(path, str) else list(path)
    opts: dict | None = None
    breaks, offset = [], 0
    for p in paths:
        side = read_capture_sidecar(p) or {}
        piece_opts = {k: side[k] for k in DECODER_FIELDS if k in side}
        if opts is None:
            opts = piece_opts
        elif piece_opts != opts:
            raise FogmonError(f"{p}{SIDECAR_SUFFIX}: decoder options {piece_opts} differ from those of "
                              f"{paths[0]}{SIDECAR_SUFFIX} ({opts}): not pieces of one capture")
        breaks += [(offset + b["offset"], float(b["missing_est"]),
                    *([Placed(b["frame"], b["missing"], b["rule"], b["wraps"])] if "missing" in b else []))
                   for b in side.get("breaks", [])]
        try:
            offset += os.path.getsize(p)
        except OSError:
            raise FogmonError(f"{p}: no such file") from None
    opts = opts or {}
    opts.update({k: v for k, v in (overrides or {}).items() if v is not None})
    if "protocol" not in opts:
        raise FogmonError(f"{paths[0]}: a raw serial capture needs `protocol` "
                          f"(or a {os.path.basename(paths[0])}{SIDECAR_SUFFIX} sidecar naming it)")
    return RawCaptureSource(paths, opts, breaks)


def open_source(path: str, opts: SourceOptions) -> RawCaptureSource:
    """The raw capture ``path`` with its sidecar's decoder options, overridden by those
    ``opts`` gives."""
    return open_raw_capture(path, opts.codec_options())
