"""Recordings made by other tools: which reader opens which file, their command-line
options, and the recording as a whole for the batch commands.

One place knows the formats (``READERS``, by suffix; a ROS 2 bag folder by its
metadata.yaml). Each reader is a module of fogmon.sources with ``open_source(path,
options) -> StampedSource`` and needs an optional dependency group of fogmon
(``pip install 'fogmon[ros]'``...); without it the error names the group."""
from __future__ import annotations

import importlib
import os
from dataclasses import dataclass

from fogmon.errors import FogmonError
from fogmon.sources import plausibility


@dataclass(frozen=True)
class Reader:
    module: str      # fogmon.sources.<module>
    what: str        # the format, for messages
    extra: str       # the optional dependency group that installs its library
    library: str     # the library's import name


_ROS = Reader("rosbag", "ROS bag / MCAP", "ros", "rosbags")
#: file suffix (lower case) -> reader
READERS = {".bag": _ROS, ".mcap": _ROS, ".db3": _ROS,
           ".ulg": Reader("ulog", "PX4 ULog", "ulog", "pyulog"),
           ".mf4": Reader("mdf", "MDF4", "mdf", "asammdf"), ".mdf": Reader("mdf", "MDF4", "mdf", "asammdf"),
           ".las": Reader("las", "LAS", "las", "lasio")}
#: the options the readers take (argparse dest -> default)
OPTIONS = ("topic", "axis", "channel", "time_channel", "rate_unit", "max_rate_dph")


def reader_for(path: str, args=None) -> Reader | None:
    """The reader of ``path`` (None: a replay log, capture or CAN log, opened elsewhere).
    An MDF4 file given ``--dbc`` or with a capture sidecar, and no ``--channel``, is a CAN
    bus log (fogmon.sources.can_source)."""
    if os.path.isdir(path):
        return _ROS if os.path.isfile(os.path.join(path, "metadata.yaml")) else None
    r = READERS.get(os.path.splitext(path)[1].lower())
    can_log = getattr(args, "dbc", None) or os.path.exists(path + ".json")   # a DBC or a capture sidecar
    if r is not None and r.module == "mdf" and can_log and not getattr(args, "channel", None):
        return None
    return r


def options(args) -> dict:
    """The reader options given on the command line (None where not given)."""
    return {k: getattr(args, k, None) for k in OPTIONS}


def open_reader(path: str, args):
    """A StampedSource for ``path`` when a reader of this module opens it, else None."""
    r = reader_for(path, args)
    if r is None:
        return None
    try:
        importlib.import_module(r.library)
    except ImportError:
        raise FogmonError(f"{path}: reading {r.what} files needs {r.library}, which is not installed: "
                          f"pip install 'fogmon[{r.extra}]'") from None
    o = options(args)
    if o["max_rate_dph"] is None:
        o["max_rate_dph"] = plausibility.GENERIC_MAX_ABS_DPH
    return importlib.import_module(f"fogmon.sources.{r.module}").open_source(path, o)


def read_recording(path: str, args=None):
    """The whole recording at ``path`` as a fogmon.recording.Recording: a replay log read
    by read_replay_log, any format of ``READERS`` through its reader."""
    from fogmon.recording import read_replay_log
    src = open_reader(os.fspath(path), args)
    return read_replay_log(path) if src is None else src.to_recording()
