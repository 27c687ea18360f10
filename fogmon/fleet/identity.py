"""Which gyro a recording of `fogmon batch` comes from (docs/batch.md, "Gyros"): the
fleet report compares and trends recordings of one gyro only, so a gyro is named by what
the recording says about its unit, never by the folder it happens to lie in alone.

From the recording's metadata (replay-log header ``# key: value`` lines, a Parquet log's
metadata, a raw capture's sidecar fields): a serial number (``SERIAL_KEYS``, the first
present) names the gyro wherever its recordings lie; else the ``sensor`` name together
with the folder (two units of one type in one folder cannot be told apart, so recordings
of one sensor type in other folders stay separate); else the recording is a gyro of its
own (no trend). ``group_by`` KEY (`fogmon batch --group-by`) uses that metadata key
instead, or ``folder`` (the folder alone, when the user says each folder is one gyro) or
``recording`` (every recording its own)."""
from __future__ import annotations

import os

#: Metadata keys that name one unit, in the order they are looked for.
SERIAL_KEYS = ("serial_number", "serial", "sn", "sensor_serial", "gyro_serial")


def source_meta(src) -> dict[str, str]:
    """The metadata a source carries: a raw capture's sidecar fields and a log's header
    metadata (an archive's: its first piece's), as text."""
    first = (getattr(src, "_sources", None) or [src])[0]
    meta = {**(getattr(src, "_options", None) or {}), **(getattr(first, "meta", None) or {})}
    return {str(k): str(v) for k, v in meta.items() if isinstance(v, (str, int, float)) and str(v).strip()}


def _folder(recording: str) -> str:
    return os.path.basename(os.path.dirname(os.path.normpath(recording))) or "."


def _name(recording: str) -> str:
    return os.path.basename(os.path.normpath(recording))


def gyro_identity(recording: str, meta: dict[str, str], group_by: str | None = None) -> tuple[str, str]:
    """(gyro, what named it) of ``recording`` with metadata ``meta`` (see the module
    docstring); ``what named it`` is the metadata key, "sensor + folder", "folder" or
    "recording"."""
    if group_by == "folder":
        return _folder(recording), "folder"
    if group_by == "recording":
        return _name(recording), "recording"
    if group_by:
        value = meta.get(group_by, "").strip()
        return (value, group_by) if value else (_name(recording), f"recording (no {group_by})")
    for key in SERIAL_KEYS:
        if meta.get(key, "").strip():
            return meta[key].strip(), key
    if meta.get("sensor", "").strip():
        return f"{meta['sensor'].strip()} in {_folder(recording)}", "sensor + folder"
    return _name(recording), "recording"
