"""The interfaces at the sources' boundary, as typing Protocols.

The rest of fogmon cannot tell a live gyro from a replay but by ``live``: it iterates
``blocks()`` and reads ``counters``. Sources convert to deg/h and s at this boundary and insert invalid
placeholder samples for anything lost (see fogmon.block). A source whose raw input can
be archived (a serial or CAN gyro) is also a ``CaptureSource``: the archive registers
itself as its ``RawTap``. Serial decoders are ``Codec``s (fogmon.sources.codecs)."""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any, Protocol, runtime_checkable

from fogmon.block import Block
from fogmon.sources.frames import Frames


class Source(Protocol):
    """What the pipeline reads."""

    #: human-readable description, e.g. "KVH DSP-1760 format A on /dev/ttyUSB0, axis z"
    name: str
    #: nominal sample rate in Hz (the uniform grid that Block samples sit on)
    sample_rate_hz: float
    #: a device read as its data arrives (serial port, CAN bus: fogmon.sources.live), never
    #: held back: the blocks it delivers while the pipeline is too far behind are dropped
    #: and counted (fogmon.pipeline.reader). False for a file or a simulation, read at the
    #: reader's pace (``OfflineSource``).
    live: bool

    @property
    def opened_s(self) -> float | None:
        """``time.monotonic()`` when a live device was first opened, None before that and
        for a source that is not live (a run of ``duration_s`` on a device that falls
        silent stops that long after it, plus some slack: fogmon.pipeline.run)."""
        ...

    @property
    def axes(self) -> tuple[str, ...]:
        """The axes of its blocks, known before the first one (() for a one-axis source;
        a three-axis KVH, several CAN or ``lines`` rate columns, a multi-axis log, a ROS bag or
        PX4 ULog IMU read without ``axis``)."""
        ...

    @property
    def n_samples(self) -> int | None:
        """Length of a finite source in samples (sizes the default window), None for a
        live or endless one."""
        ...

    @property
    def counters(self) -> dict[str, int]:
        """Running counts: frames_ok, crc_errors, bytes_skipped, seq_gaps, invalid_samples, ..."""
        ...

    def blocks(self) -> Iterator[Block]:
        """Yield blocks until the source ends (end of file, a live source's ``limit``, close())."""
        ...

    def close(self) -> None:
        """Stop and release the device/file; ``blocks()`` then ends."""
        ...

    def limit(self, n_samples: int | None) -> None:
        """End ``blocks()`` after grid sample ``n_samples`` (None: no limit); called before
        ``blocks()`` starts. A live device then decodes nothing after it, so its raw
        capture ends with the run's last sample; a source that is not live may ignore it
        (the pipeline cuts every source's blocks at the run's duration)."""
        ...


class OfflineSource:
    """The ``Source`` members about devices as a file or a simulation has them (the base
    class of those sources): not ``live``, never ``opened_s``, nothing to ``limit``."""

    live = False
    opened_s: float | None = None

    def limit(self, n_samples: int | None) -> None:
        """Nothing to do: the pipeline cuts the blocks at the run's duration."""


class RawTap(Protocol):
    """Receives a live source's raw input in stream order (the archive), possibly from
    the source's reader thread."""

    def raw(self, data: bytes) -> None:
        """Serial bytes, right after the codec decoded them."""

    def frame(self, msg: Any) -> None:
        """One received CAN frame (a can.Message)."""

    def outage(self, elapsed_s: float, missing_est: float) -> None:
        """The device was reopened after ``elapsed_s`` s; about ``missing_est`` samples lost."""

    def placed(self, frame: int, missing: int, rule: int, wraps: int = 0) -> None:
        """Before the ``frame``-th frame decoded from the next bytes the grid placed
        ``missing`` samples by its clock (``rule``: an index of fogmon.sources.grid.WHY;
        ``wraps`` whole counter wraps among them), which a replay of the bytes must repeat."""


@runtime_checkable
class CaptureSource(Source, Protocol):
    """A source whose raw input can be written as a replayable capture."""

    def capture_spec(self) -> dict[str, Any]:
        """The capture's sidecar base: ``kind`` ('serial' or 'can'), the decoder options
        (fogmon.formats.capture.DECODER_FIELDS or CAN_DECODER_FIELDS), the device; ``dbc_path`` for CAN."""
        ...

    def add_tap(self, tap: RawTap) -> None:
        """Register ``tap`` for the raw input (adding one twice is a no-op)."""
        ...

    @property
    def pending(self) -> int:
        """Bytes of a partial frame the decoder holds (0 at a frame boundary)."""
        ...


class Codec(Protocol):
    """An incremental serial decoder: bytes in, decoded frames out (deg/h)."""

    protocol: str
    sample_rate_hz: float
    aux_names: tuple[str, ...]
    #: the sequence counter's modulus, None when the protocol has no counter
    seq_modulus: int | None
    counters: dict[str, int]
    #: the axes of its frames (fogmon.sources.frames), () for one axis
    axes: tuple[str, ...]

    @property
    def pending(self) -> int:
        """Bytes of a partial frame held until more input arrives."""
        ...

    def feed(self, data: bytes) -> Frames:
        """Decode ``data`` (any chunking); frames completed by it."""
        ...

    def options(self) -> dict[str, Any]:
        """The options that rebuild this decoder (codecs.protocols.codec_from_options)."""
        ...

    def describe(self) -> str:
        """A one-line description for the source's name."""
        ...
