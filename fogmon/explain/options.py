"""What the user asked of `fogmon explain`, with the library's defaults: a frozen
dataclass that pickles for Dask and imports nothing heavy (the CLI reads its defaults
for ``--help``)."""
from __future__ import annotations

from dataclasses import dataclass

#: The sequential Monte Carlo test (``bootstrap.settled``): a decision that would name
#: something and lies within this many standard errors of its threshold's Monte Carlo
#: estimate (mismatch.undecided, ``selection.bars_undecided``) ...
SETTLE_SE = 2.0
#: ... draws the bootstrap's size again, up to this many times that size in all
MAX_GROWTH = 4


@dataclass(frozen=True)
class Options:
    """Map window (s, default duration/8), bootstrap replicates (default by length),
    family-wise significance, seed, effect budget, worker processes."""

    window_s: float | None = None
    n_boot: int | None = None
    alpha: float = 0.01
    seed: int = 12345
    max_effects: int = 8
    workers: int = 0  # 0: os.cpu_count()
