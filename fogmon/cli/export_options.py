"""``--export FORMAT FILE`` (`fogmon replay`, `fit`, `explain`): the option and the
request it makes, checked before any work (fogmon.export)."""
from __future__ import annotations

import argparse
from collections.abc import Iterable

from fogmon.export import check_export


def add_export_argument(parser: argparse.ArgumentParser) -> None:
    """``--export FORMAT FILE``."""
    parser.add_argument("--export", nargs=2, metavar=("FORMAT", "FILE"),
                        help="also write the fitted noise parameters for another tool: kalibr (imu.yaml, "
                             "continuous-time rad/s/sqrt(Hz), rad/s^2/sqrt(Hz)), ros (allan_variance_ros-style "
                             "imu.yaml) or matlab (gyroparams snippet); docs/exports.md")


def export_request(args: argparse.Namespace, inputs: Iterable[str | None] = ()) -> tuple[str, str] | None:
    """(format, file) of ``--export`` (None when not given), checked before any work: an
    unknown format or a file that cannot be written (or is one of ``inputs``) is a
    FogmonError."""
    e = getattr(args, "export", None)
    if not e:
        return None
    kind, path = e
    check_export(kind, path, inputs)
    return kind, path
