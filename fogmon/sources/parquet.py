"""A Parquet replay log (fogmon.parquet_log) replayed: the same blocks, counters and
checks as a CSV replay log (fogmon.sources.replay.ReplayLogSource), read one row group at
a time (memory of one row group and one block, whatever the file size)."""
from __future__ import annotations

from collections.abc import Sequence

from fogmon.parquet_log import ParquetRows
from fogmon.sources import plausibility
from fogmon.sources.replay import ReplayLogSource


class ParquetLogSource(ReplayLogSource):
    """``paths``: one Parquet replay log, or the files of one recording in order (an
    archive's pieces and parts). ``info``: the first file's ``fogmon`` metadata (units,
    source, sidecar facts). ``axis``: as ReplayLogSource."""

    def __init__(self, paths: str | Sequence[str], speed: float | None = None, tolerate: bool = False,
                 max_abs_dph: float = plausibility.GENERIC_MAX_ABS_DPH, axis: str | None = None) -> None:
        rows = ParquetRows(paths, tolerate=tolerate)
        super().__init__(rows.paths[0], speed=speed, tolerate=tolerate, max_abs_dph=max_abs_dph, reader=rows,
                         axis=axis)
        self.info = rows.info
        self.name = f"parquet log {rows.name}" + (f" ({rows.meta['sensor']})" if "sensor" in rows.meta else "")
