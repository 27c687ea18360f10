"""The archive's decoded samples as Parquet (``fogmon monitor --archive-format parquet``):
piece k is ``samples-NNNN.parquet`` (fogmon.formats.parquet_log; names: fogmon.formats.archive),
written so that a SIGKILL loses at most the row group being filled.

While piece k is written, each completed row group (``row_group_s`` s of samples) is
its own complete Parquet file ``samples-NNNN.parquet.parts/part-MMMMMM.parquet``
(written as ``.tmp`` and renamed, so a part file is never half-written). When the piece
ends (rotation, end of run) its parts are joined into ``samples-NNNN.parquet`` (one row
group per part, written as ``.tmp`` and renamed) and the parts folder is removed. A
reader takes, per piece, the joined file when there is one, else the parts in order
(fogmon.formats.archive.piece_files): a killed monitor's archive replays up to its last
row group. A write that fails (a full disk) leaves no ``.tmp`` file: a part that could
not be written is not there, a piece that could not be joined keeps its parts (the
OSError is raised for the archive to report)."""
from __future__ import annotations

import contextlib
import os
import shutil

from fogmon.formats.archive import PARQUET_LOG, PARTS_SUFFIX, part_name, piece_path
from fogmon.formats.parquet_log import schema, table

#: default recording time per row group (s): what a SIGKILL can cost at most
ROW_GROUP_S = 60.0


class ParquetPieces:
    """Writer of the Parquet pieces under ``directory`` at ``sample_rate_hz`` (Hz): ``write``
    appends rows (valid samples; with ``axes``, ``rate_dph`` is (n, len(axes)), written as
    ``rate_<axis>_dph`` columns) to the current piece, ``end_piece`` joins it."""

    def __init__(self, directory: str, sample_rate_hz: float, row_group_s: float = ROW_GROUP_S) -> None:
        self.directory = directory
        self.rows_per_group = max(1, int(round(row_group_s * sample_rate_hz)))
        self._piece: int | None = None
        self._schema = None
        self._buf: list = []
        self._held = 0
        self._parts = 0
        self.rows_on_disk = 0        # rows in the part files written
        self.bytes_on_disk = 0       # their size
        self.path: str | None = None   # the file being written (for a message)

    def write(self, piece: int, aux_names, meta: dict, t_s, rate_dph, aux: dict, axes: tuple[str, ...] = ()) -> None:
        if self._piece != piece:
            self.end_piece()
            self._piece, self._parts = piece, 0
            self._schema = schema(aux_names, meta, axes=axes)
            self.path = self._parts_dir()
            os.makedirs(self.path, exist_ok=False)
        tbl = table(self._schema, t_s, rate_dph, aux)
        while len(tbl):
            take = min(len(tbl), self.rows_per_group - self._held)
            self._buf.append(tbl.slice(0, take))
            self._held += take
            tbl = tbl.slice(take)
            if self._held == self.rows_per_group:
                self._write_part()

    def _parts_dir(self) -> str:
        assert self._piece is not None, "called inside a piece"
        return os.path.join(self.directory, piece_path(PARQUET_LOG, self._piece) + PARTS_SUFFIX)

    def _write_part(self) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        path = os.path.join(self._parts_dir(), part_name(self._parts + 1))
        self.path = path
        _written(lambda tmp: pq.write_table(pa.concat_tables(self._buf), tmp, compression="zstd"), path)
        self._parts += 1
        self.rows_on_disk += self._held
        self.bytes_on_disk += os.path.getsize(path)
        self._buf, self._held = [], 0

    def end_piece(self, write_held: bool = True) -> None:
        """Write the rows held (unless not ``write_held``: after a failed write) and join
        the current piece's parts (no-op without one). On an OSError the piece keeps
        its parts and is done."""
        import pyarrow.parquet as pq

        if self._piece is None:
            return
        try:
            if self._held and write_held:
                self._write_part()
            parts = self._parts_dir()
            final = os.path.join(self.directory, piece_path(PARQUET_LOG, self._piece))
            if self._parts:
                self.path = final

                def join(tmp: str) -> None:
                    with pq.ParquetWriter(tmp, self._schema, compression="zstd") as w:
                        for i in range(1, self._parts + 1):
                            w.write_table(pq.read_table(os.path.join(parts, part_name(i))))

                _written(join, final)
            shutil.rmtree(parts, ignore_errors=True)
        finally:
            self._piece, self._buf, self._held = None, [], 0


def _written(write, path: str) -> None:
    """``write(tmp)`` then rename ``tmp`` to ``path``; no ``tmp`` left on an error."""
    tmp = path + ".tmp"
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise
