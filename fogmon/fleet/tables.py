"""The two tables `fogmon batch` writes (docs/batch.md): ``windows.parquet``, one row
per (recording, axis, window), and ``recordings.parquet``, one row per (recording, axis)."""
from __future__ import annotations

import os

import numpy as np

from fogmon.outputs import written
from fogmon.sinks.base import COEFFICIENTS

WINDOWS = "windows.parquet"
RECORDINGS = "recordings.parquet"


def adev_column(tau_s: float) -> str:
    """The windows-table column of the ADEV (deg/h) at ``tau_s`` (s): ``adev_<tau>s``."""
    return f"adev_{tau_s:.6g}s"


def coefficient_columns() -> list[str]:
    """Q_arcsec, Q_arcsec_lo, Q_arcsec_hi, ... then identifiable_Q_arcsec, ..."""
    return [f"{c}{s}" for c in COEFFICIENTS for s in ("", "_lo", "_hi")] + [f"identifiable_{c}" for c in COEFFICIENTS]


def windows_table(name: str, axis: str, window_s: float, tau_s: np.ndarray, parts: list[dict]):
    """The windows of one recording (``parts``: the chunks' windows in order) as a table."""
    import pyarrow as pa

    parts = [p for p in parts if p]
    n = sum(len(p["t_end_s"]) for p in parts)
    cols = {"recording": pa.array([name] * n, pa.string()), "axis": pa.array([axis] * n, pa.string()),
            "t_end_s": np.concatenate([p["t_end_s"] for p in parts]) if n else np.zeros(0),
            "window_s": np.full(n, window_s)}
    for c in coefficient_columns():
        cols[c] = np.concatenate([p[c] for p in parts]) if n else np.zeros(0, bool if c.startswith("id") else float)
    adev = np.concatenate([p["adev"] for p in parts]) if n else np.zeros((0, len(tau_s)))
    for j, tau in enumerate(tau_s):
        cols[adev_column(tau)] = adev[:, j]
    return pa.table(cols)


def write_tables(out_dir: str, windows: list, recordings: list[dict]) -> tuple[str, str]:
    """Write both tables into ``out_dir`` (each under a temporary name, then renamed:
    never half written; a disk error is a FogmonError naming the file); windows of
    recordings with other taus get nulls in the ADEV columns they lack. Returns the two
    paths."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    w = (pa.concat_tables(windows, promote_options="default") if windows
         else pa.table({"recording": pa.array([], pa.string())}))
    adev = sorted((c for c in w.column_names if c.startswith("adev_")), key=lambda c: float(c[5:-1]))
    w = w.select([c for c in w.column_names if not c.startswith("adev_")] + adev)
    r = pa.Table.from_pylist(recordings)
    paths = []
    for tbl, name in ((w, WINDOWS), (r, RECORDINGS)):
        path = os.path.join(out_dir, name)
        with written(path, "`out`") as tmp:
            pq.write_table(tbl, tmp, compression="zstd")
        paths.append(path)
    return paths[0], paths[1]
