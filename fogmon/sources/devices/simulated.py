"""A simulated gyro as a live source (fogmon.sources.base.Source): streams
``fogmon.sim.simulate.iter_simulate`` block by block in bounded memory, as fast as
possible or paced at real time x ``speed``. Endless when neither a duration, a
recording (``like``) nor aux channels bound it; ``close()`` stops it. It can wait: the
pipeline's bounded reader queue holds it back while processing catches up."""
from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.formats.recording import Recording
from fogmon.sim.model import SensorModel, load_model
from fogmon.sim.simulate import CHUNK_SAMPLES, iter_simulate, present_samples, simulated_axes
from fogmon.sources.base import OfflineSource
from fogmon.sources.options import SourceOptions
from fogmon.sources.pacing import Pacer

#: block length (s) when paced, as for the replay sources
PACED_BLOCK_S = 0.1


class SimulatedSource(OfflineSource):
    """Source yielding a simulation of ``model`` (a SensorModel or a model file path).
    Counters: ``samples`` (valid samples yielded), ``blocks``, ``samples_missing``
    (gap placeholders copied from a ``like`` recording). ``axes``: the axes of a
    multi-axis simulation (its blocks have them; () for one axis), a sample counted
    once for all its axes."""

    def __init__(self, model: SensorModel | str, duration_s: float | None = None, like: Recording | None = None,
                 aux: dict | None = None, aux_t_s=None, seed: int | None = None, speed: float | None = None) -> None:
        what = "model"
        if not isinstance(model, SensorModel):
            what = os.path.basename(str(model))
            model = load_model(model)
        if seed is not None and not (isinstance(seed, (int, np.integer)) and seed >= 0):
            raise FogmonError(f"seed must be a non-negative integer, got {seed!r}")
        fresh = np.random.SeedSequence().entropy  # an int when drawn fresh
        self.seed = int(fresh) if seed is None else int(seed)  # type: ignore[arg-type]
        self.name = f"simulated gyro ({what}, seed {self.seed})"
        self.model = model
        self.axes = simulated_axes(model, like)
        self.sample_rate_hz = float(like.sample_rate_hz if like is not None else model.sample_rate_hz)
        #: length in samples when bounded (None: endless), the pipeline sizes its default window with it
        self.n_samples = (int(round(duration_s * self.sample_rate_hz)) if duration_s is not None
                          else int(like.grid_index()[-1]) + 1 if like is not None else None)
        self.meta: dict = {}
        seed = self.seed
        chunk = max(1, int(round(PACED_BLOCK_S * self.sample_rate_hz * speed))) if speed else CHUNK_SAMPLES
        self._it = iter_simulate(model, duration_s, like, aux, seed, aux_t_s, chunk_samples=chunk, meta_out=self.meta,
                                 where=what)
        self._pacer = Pacer(speed)
        self.counters = {"samples": 0, "blocks": 0, "samples_missing": 0}
        self._closed = False

    def blocks(self) -> Iterator[Block]:
        for b in self._it:
            if self._closed:
                return
            self._pacer.wait(float(b.t_s[0]))
            nv = int(present_samples(b).sum())
            self.counters["samples"] += nv
            self.counters["samples_missing"] += len(b) - nv
            self.counters["blocks"] += 1
            yield b

    def close(self) -> None:
        self._closed = True


def open_source(path: str, opts: SourceOptions) -> SimulatedSource:
    """The sensor model file ``path`` streamed as an endless simulation (no option applies)."""
    return SimulatedSource(path)
