"""The parametric bootstrap null of explain (docs/explain.md): simulations of the model's
stochastic part like the recording, mapped like the residual.

Cost (the part of explain that dominates): each replicate is one run of the simulator's
stochastic part `--like` the recording (bias, rotation and mean-type effects are left
out: they do not change the null of a residual) and one pass of the DAVAR engine's
compensated kernels for the map and the whole-record ADEV (no EDF work). Mean-type
effects and an outlier population (its outliers are replaced in the residual) never
change the null, so accepting them reuses it; only noise-type effects
(markov, bandwidth, vibration/temperature noise) trigger a new bootstrap. The
replicate count adapts to the record length (100 up to 1e5 samples, 60 up to 4e5,
else 40) and the family-wise threshold comes from a Gumbel law fitted to the
replicates' max |z|, so 40 replicates give a usable 1 % threshold; replicates run on
all cores.
"""
from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from fogmon.explain import mismatch
from fogmon.formats.recording import Recording
from fogmon.sim.model import SensorModel
from fogmon.sim.simulate import iter_simulate

#: Progress callback: ``progress(stage, done, total)``; total 0 announces a stage, else
#: ``done`` of ``total`` steps of it are complete.
Progress = Callable[[str, int, int], None]


def _replicate(model: SensorModel, like: Recording, grid: mismatch.Grid, seed) -> tuple[np.ndarray, np.ndarray]:
    """ln avar of the map cells and the whole record of one simulation of ``model``."""
    r = np.concatenate([b.rate_dph for b in iter_simulate(model, like=like, seed=int(seed), chunk_samples=1 << 18)])
    return mismatch.log_avar(r, np.isfinite(r), grid)


_SHARED: tuple = ()  # (model, like, grid) in a bootstrap worker process, inherited by fork


def _init_worker(shared: tuple) -> None:
    global _SHARED
    _SHARED = shared


def _replicate_in_worker(seed) -> tuple[np.ndarray, np.ndarray]:
    model, like, grid = _SHARED
    return _replicate(model, like, grid, seed)


def bootstrap(stoch: SensorModel, like: Recording, grid: mismatch.Grid, n_boot: int, seed: int,
              alpha: float, workers: int, progress: Progress | None = None) -> mismatch.Null:
    """Parametric bootstrap null: ``n_boot`` simulations of ``stoch`` like the recording,
    reported to ``progress`` replicate by replicate."""
    seeds = np.random.SeedSequence(seed).generate_state(n_boot)
    nw = max(1, min(workers or os.cpu_count() or 1, n_boot))
    report = progress or (lambda stage, done, total: None)
    parts = []
    if nw == 1 or grid.n * n_boot < 2_000_000:
        for s in seeds:
            parts.append(_replicate(stoch, like, grid, s))
            report("bootstrap", len(parts), n_boot)
    else:
        with ProcessPoolExecutor(nw, mp_context=mp.get_context("fork"), initializer=_init_worker,
                                 initargs=((stoch, like, grid),)) as ex:
            for part in ex.map(_replicate_in_worker, seeds):
                parts.append(part)
                report("bootstrap", len(parts), n_boot)
    return mismatch.build_null(np.array([c for c, _ in parts]), np.array([w for _, w in parts]), alpha)


def default_n_boot(n: int) -> int:
    """Bootstrap replicates for an ``n``-sample record (100 up to 1e5 samples, 60 up to 4e5, else 40)."""
    return 100 if n <= 100_000 else 60 if n <= 400_000 else 40
