"""A Parquet replay log (fogmon.formats.parquet_log) replayed: the same blocks, counters
and checks as a CSV replay log (fogmon.sources.files.replay_log.ReplayLogSource), read one
row group at a time (memory of one row group and one block, whatever the file size)."""
from __future__ import annotations

from collections.abc import Sequence

from fogmon.formats.parquet_log import ParquetRows
from fogmon.sources import plausibility
from fogmon.sources.files.replay_log import ReplayLogSource
from fogmon.sources.options import SourceOptions


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


def open_source(path: str | Sequence[str], opts: SourceOptions) -> ParquetLogSource:
    """The Parquet replay log ``path`` (or the files of one recording), with
    ``tolerate_bad_rows``, ``file_gate_dph`` and ``axis``."""
    return ParquetLogSource(path, tolerate=opts.tolerate_bad_rows, max_abs_dph=opts.file_gate_dph, axis=opts.axis)
