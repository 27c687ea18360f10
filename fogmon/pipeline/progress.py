"""A replay's progress bar: recording seconds done and the speed in x real time (tqdm)."""
from __future__ import annotations

import sys
from typing import TextIO


class ReplayProgress:
    """A replay's progress bar on ``stream`` (default stderr, tqdm): recording seconds
    done of ``total_s`` and the speed in x real time. Shown only when ``enabled`` (the
    caller checks that stderr is a terminal) and the total is known."""

    FORMAT = "{percentage:5.1f}%|{bar:30}| {n:.1f}/{total:.1f} s of recording{postfix} [{elapsed}<{remaining}]"

    def __init__(self, total_s: float, enabled: bool, stream: TextIO | None = None):
        self._bar = None
        if enabled and total_s > 0:   # tqdm imported only to be shown
            from tqdm import tqdm

            self._bar = tqdm(total=total_s, file=stream or sys.stderr, mininterval=0.2, bar_format=self.FORMAT)

    def update(self, done_s: float, wall_s: float) -> None:
        """``done_s`` s of recording analysed in ``wall_s`` s of wall time."""
        if self._bar is None:
            return
        if wall_s > 0:
            self._bar.set_postfix_str(f"x{done_s / wall_s:,.0f} real time", refresh=False)
        self._bar.update(min(done_s, self._bar.total) - self._bar.n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
