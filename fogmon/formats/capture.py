"""The raw-capture format (docs/formats.md): a capture file ``X`` holds the input exactly
as received (serial bytes, or a python-can ASC log of CAN frames); its sidecar ``X.json``
holds the format tag, the kind, the decoder options and the outages, so that replaying
it decodes and gates exactly like the live monitor did. The one place that writes
(fogmon.sinks.archive) and reads (fogmon.sources.files.capture) it. The values a
decoder option may take are the decoders' to know: the reader passes them (``choices``)."""
from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

from fogmon.errors import FogmonError

SIDECAR_SUFFIX = ".json"
CAPTURE_FORMAT = "fogmon capture v1"

#: The decoder options a serial capture's sidecar may hold: the names of the serial
#: codecs' options() and of fogmon.sources.codecs.protocols.make_codec's parameters.
DECODER_FIELDS = ("protocol", "sample_rate_hz", "kvh_rot", "kvh_units", "axis", "columns", "max_rate_dph",
                  "kvh_accel")
#: The decoder options a CAN capture's sidecar may hold: the names of the CAN decoder's
#: options() (fogmon.sources.codecs.can.CanDecoder); the DBC is the separate ``dbc``.
CAN_DECODER_FIELDS = ("message", "rate_signal", "rate_unit", "temp_signal", "counter_signal", "valid_signal",
                      "sample_rate_hz", "max_rate_dph")


def _text(v, folder):
    return None if isinstance(v, str) else f"expected text, got {v!r}"


def _text_or_null(v, folder):
    return None if v is None or isinstance(v, str) else f"expected text or null, got {v!r}"


def _one_of(*values):
    def check(v, folder):
        return None if v in values else f"expected one of {', '.join(map(str, values))}, got {v!r}"
    return check


def _number(minimum: float, strict: bool):
    def check(v, folder):
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and \
            (v > minimum if strict else v >= minimum)
        return None if ok else f"expected a number {'>' if strict else '>='} {minimum:g}, got {v!r}"
    return check


def _count(v, folder):
    return None if isinstance(v, int) and not isinstance(v, bool) and v >= 0 else \
        f"expected a whole number >= 0, got {v!r}"


def _file_in_folder(v, folder):
    """A file named by the sidecar must be in the sidecar's own folder: a plain file name,
    not a path (absolute, with .., or through a link leading elsewhere)."""
    if not isinstance(v, str) or not v or v in (".", "..") or os.path.basename(v) != v or "\\" in v:
        return f"must name a file in the sidecar's folder ({folder}), got {v!r}"
    real = os.path.realpath(os.path.join(folder, v))
    if os.path.dirname(real) != os.path.realpath(folder):
        return f"{v!r} leads outside the sidecar's folder ({folder})"
    return None


def _axes(v, folder):
    """The axes decoded: one ("z", as every earlier version wrote for KVH) or several
    ("x,y,z"), letters/digits (the decoder checks it has them)."""
    names = v.split(",") if isinstance(v, str) else []
    ok = names and all(a.isascii() and a.isalnum() for a in names) and len(set(names)) == len(names)
    return None if ok else f"expected an axis name or several separated by commas (x,y,z), got {v!r}"


def _breaks(v, folder):
    if not isinstance(v, list):
        return f"expected a list, got {v!r}"
    for i, b in enumerate(v):
        if not (isinstance(b, dict) and "offset" in b and "missing_est" in b and _count(b["offset"], folder) is None
                and _number(0, False)(b["missing_est"], folder) is None):
            return f"item {i}: expected {{\"offset\": bytes >= 0, \"missing_est\": samples >= 0}}, got {b!r}"
        placed = [k for k in ("frame", "missing", "rule", "wraps") if k in b]
        if placed and (len(placed) != 4 or any(_count(b[k], folder) for k in placed)):
            return (f"item {i}: a gap placed by the clock needs \"frame\", \"missing\", \"rule\" and \"wraps\" "
                    f"as counts >= 0, got {b!r}")
    return None


#: Sidecar fields -> check (None if fine, else why not). ``format`` and ``kind`` are
#: required; unknown fields are ignored (newer writers may add some). ``protocol`` and
#: ``kvh_accel`` are checked against the reader's ``choices`` (read_sidecar).
SIDECAR_FIELDS = {
    "kind": _one_of("serial", "can"), "protocol": _text, "sample_rate_hz": _number(0, True),
    "kvh_rot": _one_of("rate", "delta"), "kvh_units": _one_of("deg", "rad"), "axis": _axes,
    "kvh_accel": _text,
    "columns": _text, "max_rate_dph": _number(0, True), "breaks": _breaks, "piece": _count, "started_utc": _text,
    "port": _text, "baud": _count, "channel": _text_or_null, "interface": _text_or_null, "dbc": _file_in_folder,
    "message": _text_or_null, "rate_signal": _text_or_null, "rate_unit": _text_or_null,
    "temp_signal": _text_or_null, "counter_signal": _text_or_null, "valid_signal": _text_or_null,
}


def read_sidecar(path: str, choices: Mapping[str, Sequence[str]] | None = None) -> dict | None:
    """The capture sidecar ``path + '.json'`` as a dict (checked field by field: a bad
    one is a one-line FogmonError naming the file and the field), or None when there is
    none. ``choices``: field -> the values it may take, for the fields whose values the
    decoders define (``protocol``, ``kvh_accel``: fogmon.sources.files.capture passes
    them); without them those fields need only be text."""
    side = path + SIDECAR_SUFFIX
    if not os.path.exists(side):
        return None
    try:
        with open(side, encoding="utf-8") as fh:
            d = json.load(fh)
    except OSError as e:
        raise FogmonError(f"{side}: not a readable capture sidecar ({e.strerror})") from None
    except ValueError as e:
        raise FogmonError(f"{side}: not a readable capture sidecar (bad JSON: {e})") from None
    if not isinstance(d, dict) or d.get("format") != CAPTURE_FORMAT:
        raise FogmonError(f"{side}: not a fogmon capture sidecar (missing \"format\": \"{CAPTURE_FORMAT}\")")
    if "kind" not in d:
        raise FogmonError(f"{side}: field kind: missing")
    if "sample_rate_hz" in d and "sample_rate_hz" not in d:  # the name earlier versions wrote
        d["sample_rate_hz"] = d.pop("sample_rate_hz")
    folder = os.path.dirname(os.path.abspath(side))
    checks = {**SIDECAR_FIELDS, **{k: _one_of(*v) for k, v in (choices or {}).items()}}
    for name, check in checks.items():
        why = check(d[name], folder) if name in d else None
        if why:
            raise FogmonError(f"{side}: field {name}: {why}")
    return d


def new_sidecar(spec: dict[str, Any], started_utc: str, piece: int) -> dict[str, Any]:
    """The sidecar of a new capture piece: the source's ``capture_spec()`` (without
    ``dbc_path``), the format tag, when the run started (UTC, ISO 8601), the piece
    number and no outages yet (``breaks``)."""
    return {**spec, "format": CAPTURE_FORMAT, "started_utc": started_utc, "piece": piece, "breaks": []}


def write_sidecar(capture_path: str, sidecar: dict[str, Any]) -> None:
    """Write ``capture_path + SIDECAR_SUFFIX`` atomically (a reader never sees half of it;
    on an OSError, such as a full disk, the sidecar is as before and no temporary file
    is left)."""
    path = capture_path + SIDECAR_SUFFIX
    tmp = path + ".tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(sidecar, fh, indent=1)
            fh.write("\n")
        os.replace(tmp, path)
    except OSError:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise
