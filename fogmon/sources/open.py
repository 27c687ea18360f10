"""Opening a live or replayed source from SourceOptions: the one place that knows which
reader handles which device, file or folder (docs/sources.md, docs/readers.md).

The reader table ``READERS`` maps a file suffix to its reader (a module of
fogmon.sources with ``open_source(path, opts) -> Source``); a folder is an archive or a
ROS 2 bag (its metadata.yaml), and a file its suffix does not decide is told by its
capture sidecar or its first line. The serial protocols are the protocol table of
fogmon.sources.codecs.protocols. Used by ``fogmon monitor``, ``fogmon replay``,
``fogmon convert`` and, through ``read_recording``, the batch commands."""
from __future__ import annotations

import importlib
import os
import re
from dataclasses import dataclass
from types import ModuleType

from fogmon.errors import FogmonError
from fogmon.formats.capture import SIDECAR_SUFFIX
from fogmon.formats.recording import Recording
from fogmon.formats.replay_log import read_replay_log
from fogmon.sources.base import Source
from fogmon.sources.codecs.protocols import CODECS, PROTOCOLS, make_codec
from fogmon.sources.files.capture import read_capture_sidecar
from fogmon.sources.options import SourceOptions


@dataclass(frozen=True)
class Reader:
    """A reader: ``module`` (fogmon.sources.<module>, with ``open_source(path, opts)``),
    ``what`` it reads (for messages), the optional dependency group of fogmon (``extra``)
    that installs the ``library`` it needs (None: none), and whether the batch commands
    read it whole through its source's ``to_recording()`` (``whole``; otherwise as a
    replay log, fogmon.formats.replay_log.read_replay_log)."""

    module: str
    what: str
    extra: str | None = None
    library: str | None = None
    whole: bool = False


ROSBAG = Reader("files.rosbag", "ROS bag / MCAP", "ros", "rosbags", whole=True)
ULOG = Reader("files.ulog", "PX4 ULog", "ulog", "pyulog", whole=True)
MDF = Reader("files.mdf", "MDF4", "mdf", "asammdf", whole=True)
LAS = Reader("files.las", "LAS", "las", "lasio", whole=True)
SIMULATION = Reader("devices.simulated", "sensor model")
PARQUET_LOG = Reader("files.parquet", "Parquet replay log")
CAN_LOG = Reader("files.can_log", "CAN log")
RAW_CAPTURE = Reader("files.capture", "raw serial capture")
REPLAY_LOG = Reader("files.replay_log", "replay log")
ARCHIVE = Reader("files.archive", "archive folder")

#: file suffix (lower case) -> reader
READERS = {".bag": ROSBAG, ".mcap": ROSBAG, ".db3": ROSBAG, ".ulg": ULOG, ".mf4": MDF, ".mdf": MDF, ".las": LAS,
           ".toml": SIMULATION, ".parquet": PARQUET_LOG,
           ".asc": CAN_LOG, ".blf": CAN_LOG, ".trc": CAN_LOG, ".log": CAN_LOG}


def open_live_source(opts: SourceOptions) -> Source:
    """The live source named by ``serial`` or ``can`` (exactly one)."""
    if opts.serial and not opts.can:
        from fogmon.sources.devices.serial_port import SerialSource
        o = opts.codec_options()
        protocol = o.pop("protocol") or "kvh-a"
        codec = make_codec(protocol, **{k: v for k, v in o.items() if v is not None})
        return SerialSource(opts.serial, opts.baud or CODECS[protocol].baud, codec)
    if opts.can and not opts.serial:
        from fogmon.sources.codecs.can import load_dbc
        from fogmon.sources.devices.can_bus import CanSource
        if not opts.dbc:
            raise FogmonError("`can` needs `dbc` F describing the gyro's frames (example: "
                              "fogmon/data/gyro_example.dbc)")
        return CanSource(opts.can, opts.interface, load_dbc(opts.dbc), bitrate=opts.can_bitrate,
                         dbc_path=opts.dbc, **opts.can_options())
    raise FogmonError("give exactly one of `serial` PORT or `can` CHANNEL")


def _sniff(path: str) -> str:
    """'replay-log', 'can-csv' or 'other' from the first non-empty line."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError as e:
        raise FogmonError(f"{path}: cannot read: {e.strerror}") from None
    for raw in head.splitlines():
        s = raw.strip()
        if not s:
            continue
        if s.startswith(b"# fogmon replay log") or (b"time_s" in s and re.search(rb"rate_(\w+_)?dph", s)):
            return "replay-log"
        if s.startswith(b"timestamp,arbitration_id"):
            return "can-csv"
        if s.startswith(b"#"):
            continue
        return "other"
    return "other"


def _by_name(path: str, opts: SourceOptions) -> Reader | None:
    """The reader a folder or a file's suffix names (None: its contents decide). An MDF4
    file given ``dbc`` or with a capture sidecar, and no ``channel``, holds raw CAN
    frames: python-can reads a .mf4 as a CAN log, a .mdf is told by its contents."""
    if os.path.isdir(path):
        return ROSBAG if os.path.isfile(os.path.join(path, "metadata.yaml")) else ARCHIVE
    ext = os.path.splitext(path)[1].lower()
    r = READERS.get(ext)
    if r is MDF and (opts.dbc or os.path.exists(path + SIDECAR_SUFFIX)) and not opts.channel:
        return CAN_LOG if ext == ".mf4" else None
    return r


def _by_content(path: str, opts: SourceOptions) -> Reader:
    """The reader of a file its name does not decide: its capture sidecar's kind, else its
    first line (a replay log, a python-can CSV log), else ``protocol`` (a raw capture)."""
    side = read_capture_sidecar(path)
    kind = side.get("kind") if side else _sniff(path)
    if kind in ("can", "can-csv"):
        return CAN_LOG
    if kind == "serial" or (opts.protocol and kind != "replay-log"):
        return RAW_CAPTURE
    if kind == "replay-log" or path.lower().endswith(".csv"):
        return REPLAY_LOG
    raise FogmonError(f"{path}: not a replay log; for a raw serial capture give `protocol` "
                      f"({', '.join(PROTOCOLS)}), for a CAN log use .asc/.blf/.trc/.csv/.log with `dbc`")


def reader_for(path: str, opts: SourceOptions | None = None) -> Reader:
    """The reader of ``path`` (a file or folder that exists)."""
    opts = SourceOptions() if opts is None else opts
    r = _by_name(path, opts)
    return r if r is not None else _by_content(path, opts)


def _module(r: Reader, path: str) -> ModuleType:
    """The module of reader ``r``; a one-line FogmonError naming the extra to install when
    its library is missing."""
    if r.library is not None:
        try:
            importlib.import_module(r.library)
        except ImportError:
            raise FogmonError(f"{path}: reading {r.what} files needs {r.library}, which is not installed: "
                              f"pip install 'fogmon[{r.extra}]'") from None
    return importlib.import_module(f"fogmon.sources.{r.module}")


def open_replay_source(path: str | os.PathLike, opts: SourceOptions | None = None) -> Source:
    """A source replaying ``path``: a replay-log CSV or Parquet log, a raw serial capture
    (protocol from ``protocol`` or its ``.json`` sidecar), a CAN log (.asc .blf .trc
    .csv .log with ``dbc`` or a sidecar), another tool's recording (ROS bag/MCAP, PX4
    ULog, MDF4, LAS), a sensor model (its endless simulation) or an archive folder
    (fogmon.sources.files.archive). Not paced: the pipeline paces (``realtime``)."""
    opts = SourceOptions() if opts is None else opts
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FogmonError(f"{path}: no such file")
    r = reader_for(path, opts)
    return _module(r, path).open_source(path, opts)


def read_recording(path: str | os.PathLike, opts: SourceOptions | None = None) -> Recording:
    """The whole recording at ``path`` in memory (the batch commands): another tool's
    recording through its reader (``Reader.whole``), anything else as a replay log
    (read_replay_log: CSV or Parquet)."""
    opts = SourceOptions() if opts is None else opts
    path = os.fspath(path)
    r = _by_name(path, opts)
    if r is not None and r.whole:
        return _module(r, path).open_source(path, opts).to_recording()
    return read_replay_log(path)
