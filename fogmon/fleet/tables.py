"""The tables `fogmon batch` writes (docs/batch.md): ``windows.parquet``, one row per
(recording, axis, window), and ``recordings.parquet``, one row per (recording, axis); of
recordings with accelerometers also ``accel_windows.parquet`` and
``accel_recordings.parquet``, the same per (recording, accelerometer) with the IEEE Std
1293 coefficients and the ADEV in micro-g."""
from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from fogmon.outputs import written
from fogmon.sinks.base import ACCEL_COEFFICIENTS, COEFFICIENTS

WINDOWS = "windows.parquet"
RECORDINGS = "recordings.parquet"
ACCEL_WINDOWS = "accel_windows.parquet"
ACCEL_RECORDINGS = "accel_recordings.parquet"


def adev_column(tau_s: float, accel: bool = False) -> str:
    """The windows-table column of the ADEV (deg/h) at ``tau_s`` (s): ``adev_<tau>s``; of
    an accelerometer (micro-g) ``adev_ug_<tau>s``."""
    return f"adev_{'ug_' if accel else ''}{tau_s:.6g}s"


def coefficient_columns(names=COEFFICIENTS) -> list[str]:
    """Q_arcsec, Q_arcsec_lo, Q_arcsec_hi, ... then identifiable_Q_arcsec, ... (``names``
    ACCEL_COEFFICIENTS: the accelerometers' Q_mps, VRW_mpsph, ...)."""
    return [f"{c}{s}" for c in names for s in ("", "_lo", "_hi")] + [f"identifiable_{c}" for c in names]


def windows_table(name: str, axis: str, window_s: float, tau_s: np.ndarray, parts: list[dict], accel: bool = False):
    """The windows of one recording's axis (``parts``: the chunks' windows in order) as a
    table; with ``accel`` of its accelerometer ``axis`` (column ``accel``, IEEE Std 1293
    coefficients, ADEV in micro-g)."""
    import pyarrow as pa

    parts = [p for p in parts if p]
    n = sum(len(p["t_end_s"]) for p in parts)
    cols = {"recording": pa.array([name] * n, pa.string()), ("accel" if accel else "axis"): pa.array([axis] * n,
                                                                                                    pa.string()),
            "t_end_s": np.concatenate([p["t_end_s"] for p in parts]) if n else np.zeros(0),
            "window_s": np.full(n, window_s)}
    for c in coefficient_columns(ACCEL_COEFFICIENTS if accel else COEFFICIENTS):
        cols[c] = np.concatenate([p[c] for p in parts]) if n else np.zeros(0, bool if c.startswith("id") else float)
    adev = np.concatenate([p["adev"] for p in parts]) if n else np.zeros((0, len(tau_s)))
    for j, tau in enumerate(tau_s):
        cols[adev_column(tau, accel)] = adev[:, j]
    return pa.table(cols)


def write_tables(out_dir: str, windows: list, recordings: list[dict], accel_windows: Sequence = (),
                 accel_recordings: Sequence[dict] = ()) -> tuple[str, str]:
    """Write the tables into ``out_dir`` (each under a temporary name, then renamed:
    never half written, a disk error is a FogmonError naming the file; the accelerometer
    tables only when some recording has accelerometers, else those of an earlier run
    there are removed); windows of recordings with other taus get
    nulls in the ADEV columns they lack. Returns the paths of the two gyro tables."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    tables = [(_windows(windows), WINDOWS), (pa.Table.from_pylist(recordings), RECORDINGS)]
    if accel_recordings:
        tables += [(_windows(list(accel_windows)), ACCEL_WINDOWS), (pa.Table.from_pylist(list(accel_recordings)),
                                                                   ACCEL_RECORDINGS)]
    else:
        for stale in (ACCEL_WINDOWS, ACCEL_RECORDINGS):
            if os.path.exists(os.path.join(out_dir, stale)):
                os.remove(os.path.join(out_dir, stale))
    paths = []
    for tbl, name in tables:
        path = os.path.join(out_dir, name)
        with written(path, "`out`") as tmp:
            pq.write_table(tbl, tmp, compression="zstd")
        paths.append(path)
    return paths[0], paths[1]


def _windows(windows: list):
    """The windows tables as one, ADEV columns in increasing tau at the end."""
    import pyarrow as pa

    w = (pa.concat_tables(windows, promote_options="default") if windows
         else pa.table({"recording": pa.array([], pa.string())}))
    adev = sorted((c for c in w.column_names if c.startswith("adev_")), key=lambda c: float(c.rsplit("_", 1)[1][:-1]))
    return w.select([c for c in w.column_names if not c.startswith("adev_")] + adev)
