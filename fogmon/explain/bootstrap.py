"""The parametric bootstrap null of explain (docs/explain.md): simulations of the model's
stochastic part on the recording's grid (``replicas.Replicas``), mapped like the
residual with the DAVAR engine's compensated kernels.

Cost (the part of explain that dominates): each replicate is one draw of the stochastic
part (bias, rotation and mean-type effects are left out: they do not change the null of
a residual; one FFT of 2n for every stationary Gaussian term) and one pass of the DAVAR
kernels for the map and the whole-record ADEV (no EDF work). Mean-type effects and an
outlier population (its outliers are replaced in the residual) never change the null,
so accepting them reuses it; only noise-type effects (markov, bandwidth,
vibration/temperature noise, vibration lines, a corrected [noise]) trigger a new
bootstrap. The replicate count adapts to the record length (100 up to 1e5 samples, 60
up to 4e5, else 40) and the family-wise threshold comes from a Gumbel law fitted to
the replicates' max |z|, so 40 replicates give a usable 1 % threshold; replicates run
on all cores. When the model holds a rate random walk, each replicate also gives the
mean-type candidates' gains, whose law sets their chance bars (``scan_null``).

The sequential Monte Carlo test (``settled``): a fitted threshold or chance bar has a
Monte Carlo standard error (``mismatch.Gumbel.isf_se``, the delta method under the
Gumbel law: 3.92 sd / sqrt(B) at alpha 1 %, about 0.14 in z at B = 100). When a
decision lies within ``SETTLE_SE`` of them (the map's or whole-record ADEV's largest
|z|, ``mismatch.undecided``; a candidate's gain at its chance bar,
``selection.bars_undecided``), B more replicates are drawn (``extended``: the next
seeds of the same SeedSequence stream, so B + B drawn in steps are the 2 B drawn at
once) and the null refitted, up to ``MAX_GROWTH`` x B; a clear-cut decision draws
nothing extra.
"""
from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from typing import Any

import numpy as np

from fogmon.explain import mismatch
from fogmon.explain.options import MAX_GROWTH
from fogmon.explain.replicas import Replicas
from fogmon.explain.scan_null import ScanGains, calibrated_kinds, scan_bars

#: Progress callback: ``progress(stage, done, total)``; total 0 announces a stage, else
#: ``done`` of ``total`` steps of it are complete.
Progress = Callable[[str, int, int], None]

#: below this many samples x replicates the replicates run in this process (a pool costs more)
POOL_MIN_WORK = 2_000_000

_SHARED: tuple = ()  # (replicas, fn) in a worker process, inherited by fork


def _init_worker(shared: tuple) -> None:
    global _SHARED
    _SHARED = shared


def _in_worker(seed) -> Any:
    replicas, fn = _SHARED
    return fn(replicas.draw(int(seed)))


#: Where replicates run: ``mapper(fn, replicas, seeds)`` returns [fn(replicas.draw(s)) for s
#: in seeds], in order (``fn`` and ``replicas`` pickle): e.g. as tasks of a Dask cluster
#: (fogmon.fleet.tasks). None: on this machine's cores (``map_replicates``).
Mapper = Callable[[Callable[[np.ndarray], Any], Replicas, Sequence[int]], list]


def map_replicates(replicas: Replicas, seeds: np.ndarray, fn: Callable[[np.ndarray], Any], workers: int,
                   progress: Progress | None = None, stage: str = "bootstrap", mapper: Mapper | None = None) -> list:
    """``fn(replicate)`` for the replicate of every seed (deg/h, NaN where not valid), in
    order: by ``mapper``, else on ``workers`` processes (0: all cores; in this process
    when it is a daemon, e.g. a Dask worker, which may not start processes);
    ``progress(stage, done, total)`` replicate by replicate."""
    n_rep = len(seeds)
    nw = 1 if mp.current_process().daemon else max(1, min(workers or os.cpu_count() or 1, n_rep))
    report = progress or (lambda stage, done, total: None)
    if mapper is not None:
        out = list(mapper(fn, replicas, [int(s) for s in seeds]))
        report(stage, n_rep, n_rep)
        return out
    out = []
    if nw == 1 or replicas.n * n_rep < POOL_MIN_WORK:
        for s in seeds:
            out.append(fn(replicas.draw(int(s))))
            report(stage, len(out), n_rep)
        return out
    with ProcessPoolExecutor(nw, mp_context=mp.get_context("fork"), initializer=_init_worker,
                             initargs=((replicas, fn),)) as ex:
        for part in ex.map(_in_worker, seeds):
            out.append(part)
            report(stage, len(out), n_rep)
    return out


def replicate_seeds(seed: int, n_boot: int) -> np.ndarray:
    """The seeds of a bootstrap's ``n_boot`` replicates."""
    return np.random.SeedSequence(seed).generate_state(n_boot)


class _MapOf:
    """ln avar of the map cells and the whole record of a replicate, and the gains of
    the candidates ``scans`` calibrates on it (scan_null.ScanGains; picklable)."""

    def __init__(self, grid: mismatch.Grid, scans: ScanGains | None = None):
        self.grid, self.scans = grid, scans

    def __call__(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
        cells, whole = mismatch.log_avar(r, np.isfinite(r), self.grid)
        return cells, whole, (self.scans(r) if self.scans is not None else {})


def _replicate(replicas: Replicas, grid: mismatch.Grid, seeds: np.ndarray, workers: int, progress: Progress | None,
               mapper: Mapper | None, stage: str = "bootstrap") -> list:
    """(cells, whole, gains) of the replicates of ``seeds`` (``_MapOf``; the gains of the
    candidates ``scan_null.calibrated_kinds`` names)."""
    kinds = calibrated_kinds(replicas.stoch, float(replicas.t_s[-1] - replicas.t_s[0]))
    scans = ScanGains(replicas.stoch, replicas.t_s, replicas.aux, replicas.valid, kinds) if kinds else None
    return map_replicates(replicas, seeds, _MapOf(grid, scans), workers, progress, stage, mapper)


def _null_of(cells: np.ndarray, whole: np.ndarray, gains: tuple, alpha: float, seed: int) -> mismatch.Null:
    null = mismatch.build_null(cells, whole, alpha)
    bars, se = scan_bars(list(gains), alpha)
    return replace(null, seed=seed, gains=gains, scan_bars=bars, scan_bar_se=se)


def bootstrap(replicas: Replicas, grid: mismatch.Grid, n_boot: int, seed: int, alpha: float, workers: int,
              progress: Progress | None = None, mapper: Mapper | None = None) -> mismatch.Null:
    """Parametric bootstrap null: ``n_boot`` replicates of ``replicas`` (seeds from
    ``seed``) mapped on ``grid`` (by ``mapper``, else on ``workers`` processes), reported
    to ``progress`` replicate by replicate; with the chance bars of the candidates
    ``scan_null.calibrated_kinds`` names, measured on the same replicates."""
    parts = _replicate(replicas, grid, replicate_seeds(seed, n_boot), workers, progress, mapper)
    return _null_of(np.array([p[0] for p in parts]), np.array([p[1] for p in parts]),
                    tuple(p[2] for p in parts), alpha, seed)


def extended(null: mismatch.Null, replicas: Replicas, grid: mismatch.Grid, n_more: int, workers: int,
             progress: Progress | None = None, mapper: Mapper | None = None) -> mismatch.Null:
    """``null`` (a ``bootstrap`` of ``replicas`` on ``grid``) with ``n_more`` replicates
    more: the next seeds of the same stream (``replicate_seeds(null.seed, B + n_more)``
    starts with the B seeds ``null`` used), so the result is the bootstrap of B + n_more
    replicates, whether drawn at once or in steps."""
    b = null.n_replicates
    assert null.cells is not None and null.whole is not None, "a null built by bootstrap()"
    parts = _replicate(replicas, grid, replicate_seeds(null.seed, b + n_more)[b:], workers, progress, mapper,
                       "bootstrap extension")
    return _null_of(np.concatenate((null.cells, [p[0] for p in parts])),
                    np.concatenate((null.whole, [p[1] for p in parts])),
                    null.gains + tuple(p[2] for p in parts), null.alpha, null.seed)


def settled(null: mismatch.Null, undecided: Callable[[mismatch.Null], bool], more: Callable[[mismatch.Null],
            mismatch.Null], n_boot: int) -> mismatch.Null:
    """The sequential Monte Carlo test: ``null`` (of ``n_boot`` replicates or more) grown
    by ``more`` (``n_boot`` replicates more each time, ``extended``) while
    ``undecided(null)`` says its Monte Carlo error may decide, up to ``MAX_GROWTH``
    x ``n_boot`` replicates; a clear-cut decision draws nothing."""
    while null.n_replicates < MAX_GROWTH * n_boot and undecided(null):
        null = more(null)
    return null


def default_n_boot(n: int) -> int:
    """Bootstrap replicates for an ``n``-sample record (100 up to 1e5 samples, 60 up to 4e5, else 40)."""
    return 100 if n <= 100_000 else 60 if n <= 400_000 else 40
