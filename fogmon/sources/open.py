"""Opening a live or replayed source from SourceOptions: the one place that knows which
reader handles which device, file or folder (docs/sources.md, docs/readers.md).

The reader table ``READERS`` maps a file suffix to its reader (a module of
fogmon.sources with ``open_source(path, opts) -> Source``); a folder is an archive or a
ROS 2 bag (its metadata.yaml), and a file its suffix does not decide is told by its
capture sidecar or its first line. The serial protocols are the protocol table of
fogmon.sources.codecs.protocols. Used by ``fogmon monitor``, ``fogmon replay``,
``fogmon convert``, ``fogmon info`` (``file_info``) and, through ``read_recording``, the
batch commands.

Every file reader is called through ``_guarded``: an exception a reader or its library
raises on a corrupt file (other than a FogmonError) becomes one line naming the file, the
format and what was wrong, never a traceback; the libraries' own output is kept off the
terminal by each reader (fogmon.sources.files.listing.quiet)."""
from __future__ import annotations

import importlib
import math
import os
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from types import ModuleType
from typing import TypeVar

import numpy as np

from fogmon.errors import FogmonError, FogmonWarning
from fogmon.formats.capture import SIDECAR_SUFFIX
from fogmon.formats.recording import Recording, check_stated_rate
from fogmon.formats.replay_log import read_replay_log
from fogmon.sources import plausibility
from fogmon.sources.base import Source
from fogmon.sources.codecs.protocols import CODECS, PROTOCOLS, make_codec
from fogmon.sources.files.capture import read_capture_sidecar
from fogmon.sources.files.listing import Entry, reading, stamped_entry
from fogmon.sources.options import SourceOptions

T = TypeVar("T")


@dataclass(frozen=True)
class Reader:
    """A reader: ``module`` (fogmon.sources.<module>, with ``open_source(path, opts)``),
    ``what`` it reads (for messages), the optional dependency group of fogmon (``extra``)
    that installs the ``library`` it needs (None: none), and whether the batch commands
    read it whole through its source's ``to_recording()`` (``whole``; a replay log as
    fogmon.formats.replay_log.read_replay_log, anything else from its blocks). A module
    with ``info(path, opts) -> list[Entry]`` lists what the file holds (``fogmon info``);
    the others are listed from their recording."""

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
CAN_LOG = Reader("files.can_log", "CAN log", whole=True)
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


def _guarded(r: Reader, path: str, call: Callable[[], T]) -> T:
    """``call()``, with any exception other than a FogmonError turned into one line naming
    the file, the format and the exception (a corrupt file, whatever library reads it)."""
    with reading(f"{path}: not a readable {r.what} file", silent=False):
        return call()
    raise AssertionError("unreachable")


#: the reader options a replay log (CSV or Parquet) does not take: it holds its own time stamps, rates in deg/h
#: and stated rate (docs/formats.md) and reads only axis, max_rate_dph, force_rate and tolerate_bad_rows
_NOT_FOR_REPLAY_LOGS = ("protocol", "sample_rate_hz", "kvh_rot", "kvh_units", "kvh_accel", "columns", "dbc",
                        "can_message", "can_rate", "can_rate_unit", "can_temp", "can_counter", "can_valid", "topic",
                        "channel", "time_channel", "rate_unit", "accel_channels", "resample_hz")


def _check_applies(r: Reader, path: str, opts: SourceOptions) -> None:
    """A FogmonError when options given do not apply to a replay log ``path`` (found by an
    outside check: `topic`, `channel`, `dbc`, `protocol` on a replay log were silently
    ignored)."""
    if r not in (REPLAY_LOG, PARQUET_LOG):
        return
    given = [f for f in _NOT_FOR_REPLAY_LOGS if getattr(opts, f) is not None]
    if given:
        raise FogmonError(f"{path}: a {r.what} (time_s and rate columns in deg/h, its own sample_rate_hz; "
                          f"docs/formats.md): " + ", ".join(f"`{f}`" for f in given)
                          + f" do{'es' if len(given) == 1 else ''} not apply to it")


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
    _check_applies(r, path, opts)
    mod = _module(r, path)
    return _guarded(r, path, lambda: mod.open_source(path, opts))


def read_recording(path: str | os.PathLike, opts: SourceOptions | None = None) -> Recording:
    """The whole recording at ``path`` in memory (the batch commands): a replay log as
    read_replay_log (CSV or Parquet; its stated rate checked against its time stamps
    unless ``force_rate``), another tool's recording through its reader
    (``Reader.whole``), anything else (a raw capture, an archive) from its source's
    blocks (the valid samples on their grid times)."""
    opts = SourceOptions() if opts is None else opts
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FogmonError(f"{path}: no such file")
    r = reader_for(path, opts)
    _check_applies(r, path, opts)
    if r in (REPLAY_LOG, PARQUET_LOG):
        rec = read_replay_log(path)
        if not opts.force_rate:
            check_stated_rate(rec.meta, rec.t_s, rec.name)
        return _plausible(rec, opts.file_gate_dph)
    if r is SIMULATION:
        raise FogmonError(f"{path}: a sensor model, not a recording (fogmon sim turns it into one)")
    mod = _module(r, path)
    if r.whole:
        return _guarded(r, path, lambda: mod.open_source(path, opts).to_recording())
    return _guarded(r, path, lambda: recording_of(mod.open_source(path, opts), path))


def _plausible(rec: Recording, gate: float) -> Recording:
    """``rec`` without the samples whose rate (on any axis) is beyond the plausibility gate
    ``gate`` (deg/h, ``SourceOptions.file_gate_dph``), as the streaming replay makes them
    invalid: they become time gaps, counted in a FogmonWarning (``implausible_samples``);
    a FogmonError when none is left."""
    rate, n = plausibility.gate(rec.rate_dph, gate)
    if not n:
        return rec
    gated = np.isnan(rate) & ~np.isnan(rec.rate_dph)
    keep = ~(gated if gated.ndim == 1 else gated.any(axis=1))
    if not keep.any():
        raise FogmonError(f"{rec.name}: no valid samples: every rate is beyond the plausibility gate "
                          f"+-{gate:.6g} deg/h (`max_rate_dph`)")
    warnings.warn(FogmonWarning(f"{rec.name}: {len(keep) - int(keep.sum())} sample(s) with a rate beyond the "
                                f"plausibility gate +-{gate:.6g} deg/h left out as time gaps "
                                f"({plausibility.COUNTER}; `max_rate_dph` sets the gate)"), stacklevel=2)
    kept, file_line = np.flatnonzero(keep), rec.line_of
    line_of = (lambda i: file_line(int(kept[i]))) if file_line is not None else None  # noqa: E731
    return replace(rec, t_s=rec.t_s[keep], rate_dph=rec.rate_dph[keep], aux={k: v[keep] for k, v in rec.aux.items()},
                   line_of=line_of)


def recording_of(source: Source, path: str) -> Recording:
    """The samples of a finite ``source`` valid on every axis, on their grid times, with
    ``sample_rate_hz`` metadata (a Recording as read_replay_log gives one)."""
    t: list[np.ndarray] = []
    rate: list[np.ndarray] = []
    aux: dict[str, list[np.ndarray]] = {}
    axes: tuple[str, ...] = ()
    for b in source.blocks():
        keep = b.valid.all(axis=1) if b.valid.ndim == 2 else b.valid
        axes = b.axes
        t.append(b.t_s[keep])
        rate.append(b.rate_dph[keep])
        for k, v in b.aux.items():
            aux.setdefault(k, []).append(v[keep])
    source.close()
    if not t or not sum(len(x) for x in t):
        raise FogmonError(f"{path}: no valid samples")
    return Recording(np.concatenate(t), np.concatenate(rate), {k: np.concatenate(v) for k, v in aux.items()},
                     {"sample_rate_hz": repr(source.sample_rate_hz)}, path=path, axes=axes)


#: units of the replay log's columns with a fixed meaning (docs/formats.md)
COLUMN_UNITS = {"time_s": "s", "temp_c": "deg C", "rot_dps": "deg/s", "vib_g": "g", "depth_m": "m"}


def _column_unit(name: str) -> str:
    for suffix, unit in (("_dph", "deg/h"), ("_dps", "deg/s"), ("_g", "g"), ("_c", "deg C"), ("_m", "m"),
                         ("_s", "s")):
        if name.endswith(suffix):
            return COLUMN_UNITS.get(name, unit)
    return ""


def _recording_entries(rec: Recording, what: str) -> list[Entry]:
    """One Entry per column of a recording (rate columns, then aux), counted where finite."""
    cols = [(f"rate_{a}_dph" if a else "rate_dph", rec.rate_dph[:, j] if rec.axes else rec.rate_dph)
            for j, a in enumerate(rec.axes or ("",))]
    out = []
    for name, v in [*cols, *rec.aux.items()]:
        ok = np.isfinite(v)
        out.append(stamped_entry(name, what, rec.t_s[ok], _column_unit(name)))
    return out


def file_info(path: str | os.PathLike, opts: SourceOptions | None = None) -> list[Entry]:
    """What the file or folder ``path`` holds: one Entry per topic, channel, signal or
    column (``fogmon info``). A FogmonError naming the file when it is unreadable."""
    opts = SourceOptions() if opts is None else opts
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FogmonError(f"{path}: no such file")
    r = reader_for(path, opts)
    mod = _module(r, path)
    if hasattr(mod, "info"):
        return _guarded(r, path, lambda: mod.info(path, opts))
    if r is SIMULATION:
        src = _guarded(r, path, lambda: mod.open_source(path, opts))
        return [Entry("rate_dph", "sensor model (an endless simulation)", 0, src.sample_rate_hz, math.nan, "deg/h")]
    if r in (REPLAY_LOG, PARQUET_LOG):
        return _guarded(r, path, lambda: _recording_entries(read_replay_log(path, tolerate=opts.tolerate_bad_rows),
                                                            "column"))
    rec = read_recording(path, opts)
    return _recording_entries(rec, f"{r.what} samples")
