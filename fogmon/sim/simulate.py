"""Turn a SensorModel into samples: batch (``simulate`` -> Recording) or streaming
(``iter_simulate`` -> Blocks of bounded size, same numbers for the same seed).

The gyro reads (docs/formats.md)
    bias_dph + 3600 rot_dps + Q + N(t) white + B flicker + K random walk + R ramp
    + markov terms + mean-type effects,
then passes through the ``bandwidth`` filters, if any. N(t) = N0 + the white-level
effects (vibration_noise, temperature_noise), floored at 0, scales one white sequence.

Time base and aux channels come from, in order of precedence:
- ``like``: a Recording; its sample times and every aux column are copied exactly.
  Missing samples (time gaps) are simulated on the uniform grid (aux interpolated
  there) so that the noise and the filters run continuously, and left out of the
  output (invalid placeholders in the streamed blocks).
- ``aux`` (+ optional ``aux_t_s``): aux channels sampled at ``aux_t_s`` (default: the
  model's sample times from 0); they are interpolated linearly onto the sample times.
  This is how the scenario generators (fogmon.sim.scenarios) drive a simulation.
- ``duration_s`` alone: no aux channels.

Random streams: one SeedSequence(seed) spawns an independent stream per term (Q, N,
B, K, then one per effect), so adding an effect does not change the other terms'
realization. ``seed=None`` picks fresh entropy and reports it in ``meta['seed']``.

Several axes (the model's [noise.<axis>] tables, else the axes of ``like``, else the
``axes`` asked for, e.g. a scenario's): every axis is simulated as the one-axis gyro
``model.for_axis(axis)`` (its noise, the effects that act on it) on the shared time
base, seeing the aux channels ``fogmon.block.axis_aux`` gives it (shared ones and its
own ``<ch>_<axis>``). SeedSequence(seed) first spawns one child per axis, which then
spawns that axis's term streams as above: the noise of different axes is independent,
while a shared aux channel is a common cause (one ``vib_g`` sets the white-noise level
of every axis, one ``temp_c`` drives every axis's thermal drift). A one-axis run keeps
the streams above, so its output for a given seed is what it always was. An
``aux_response`` term on another axis's rate column (``rate_x_dph``) reads that axis's
simulated rate before its own cross terms and filters (``_CrossRates``, docs/sim.md).
"""
from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterator

import numpy as np

from fogmon.block import Block, axis_aux
from fogmon.errors import FogmonError
from fogmon.formats.recording import Recording
from fogmon.sim import effects as fx
from fogmon.sim.features import channels_of, other_axis, parse_feature
from fogmon.sim.model import EFFECT_KINDS, SensorModel, validate_model
from fogmon.sim.noise import Flicker, RandomWalk, WhiteAngle, WhiteRate, default_flicker_tau_hi_s, ramp_dph

#: samples per streamed block by default (bounded memory; about 30 MB of work arrays)
CHUNK_SAMPLES = 65536


class _Plan:
    """Where the samples come from: grid size, times, aux, which grid points exist."""

    src_t: np.ndarray                   # times of the recording or aux samples (s)
    src_aux: dict[str, np.ndarray]      # their aux channels
    idx: np.ndarray                     # like: grid index of each recorded sample
    n: int | None                       # samples to simulate, None = endless
    t0: float                           # time of grid sample 0 (s)

    def __init__(self, model: SensorModel, duration_s, like, aux, aux_t_s):
        self.sample_rate_hz = float(like.sample_rate_hz if like is not None else model.sample_rate_hz)
        self.like = like
        if like is not None:
            self._like(like, duration_s)
        elif aux:
            self._aux(aux, aux_t_s, duration_s)
        else:
            self.src_t, self.src_aux, self.t0, self.idx = np.empty(0), {}, 0.0, np.empty(0, np.int64)
            if duration_s is not None and not (duration_s > 0 and math.isfinite(duration_s)):
                raise FogmonError(f"duration_s must be a positive number of seconds, got {duration_s!r}")
            self.n = None if duration_s is None else int(round(duration_s * self.sample_rate_hz))
        if self.n is not None and self.n < 1:
            raise FogmonError("nothing to simulate: the duration is shorter than one sample period")

    def _like(self, like: Recording, duration_s) -> None:
        """On the grid of a recording: its samples, times and aux channels."""
        self.idx = like.grid_index()
        self.n = int(self.idx[-1]) + 1 if len(self.idx) else 0
        self.t0 = float(like.t_s[0])
        self.src_t = like.t_s
        self.src_aux = like.aux
        if duration_s is not None:
            raise FogmonError("give either a recording to simulate like, or a duration, not both")

    def _aux(self, aux: dict, aux_t_s, duration_s) -> None:
        """Along given aux channels (at ``aux_t_s`` s, or one per sample)."""
        self.src_aux = {k: np.asarray(v, dtype=float) for k, v in aux.items()}
        lens = {len(v) for v in self.src_aux.values()}
        if len(lens) != 1:
            raise FogmonError("aux channels must all have the same length")
        m = lens.pop()
        self.src_t = (np.arange(m) / self.sample_rate_hz if aux_t_s is None else np.asarray(aux_t_s, dtype=float))
        if len(self.src_t) != m or m < 1:
            raise FogmonError("aux_t_s must have one time per aux sample (and at least one)")
        self.t0 = float(self.src_t[0])
        step = float(self.src_t[1] - self.src_t[0]) if m > 1 and aux_t_s is not None else 1.0 / self.sample_rate_hz
        span = float(self.src_t[-1] - self.src_t[0]) + step
        if duration_s is not None and duration_s > span + 1e-9 * span:
            raise FogmonError(f"duration_s {duration_s:g} s is longer than the aux channels "
                              f"({span:g} s); they would have to be invented")
        self.n = int(round((duration_s if duration_s is not None else span) * self.sample_rate_hz))
        self.idx = np.empty(0, np.int64)       # every grid sample is present

    @property
    def duration_s(self) -> float | None:
        return None if self.n is None else self.n / self.sample_rate_hz

    def chunk(self, k0: int, k1: int):
        """(t_s, aux, present) on grid samples [k0, k1): times, aux channels and the
        mask of samples that exist in the output."""
        k = np.arange(k0, k1)
        t = self.t0 + k / self.sample_rate_hz
        present = np.ones(len(k), dtype=bool)
        aux = {}
        if self.like is not None:
            lo, hi = np.searchsorted(self.idx, [k0, k1])
            pos = self.idx[lo:hi] - k0
            present[:] = False
            present[pos] = True
            t[pos] = self.src_t[lo:hi]
            for name, v in self.src_aux.items():
                a = np.interp(t, self.src_t, v) if not present.all() else np.empty(len(k))
                a[pos] = v[lo:hi]
                aux[name] = a
        elif self.src_aux:
            for name, v in self.src_aux.items():
                aux[name] = np.interp(t, self.src_t, v)
        return t, aux, present


def _check_aux(model: SensorModel, have: set[str], axis: str = "", rates: tuple[str, ...] = (),
               where: str = "model") -> None:
    """FogmonError when an effect of ``model`` (named ``where`` in messages: its file)
    needs an aux channel not in ``have`` (the channels axis ``axis`` sees; "" for a
    one-axis run) or, for an ``aux_response``, a channel neither there nor a rate column
    of another simulated axis (``rates``: the simulated axes) - or the axis's own rate
    column."""
    on = f" on axis {axis}" if axis else ""
    for i, e in enumerate(model.effects):
        need = [EFFECT_KINDS[e.kind].aux] if EFFECT_KINDS[e.kind].aux else []
        if e.kind == "aux_response":
            need = [c for c in channels_of(e.params["terms"]) if other_axis(c) not in rates]
            own = f"rate_{axis}_dph"
            if axis and any(own in parse_feature(t["feature"]).names for t in e.params["terms"]):
                raise FogmonError(f"{where}: [[effect]] #{i + 1} (aux_response){on} reads {own}, the axis's own "
                                  f"rate: a feature is an aux channel or another axis's rate")
        for c in need:
            if c not in have:
                raise FogmonError(f"{where}: [[effect]] #{i + 1} ({e.kind}){on} needs the aux channel {c!r}, which the "
                                  f"input lacks (have: {', '.join(sorted(have)) or 'none'}); simulate `like` a "
                                  f"recording with that column or use a `scenario`")


def _reads_rates(e, rates: tuple[str, ...]) -> bool:
    """Whether effect ``e`` is an ``aux_response`` reading a simulated axis's rate column."""
    return e.kind == "aux_response" and any(other_axis(c) in rates for c in channels_of(e.params["terms"]))


class _Parts:
    """The terms of one axis's simulated rate, built once per run from its one-axis
    model (random generators seeded from ``rngs``: Q, N, B, K, then one per effect);
    ``view`` gives the aux channels the axis sees from all of them. ``cross``: its
    ``aux_response`` effects that read other simulated axes' rates (``rates``)."""

    def __init__(self, model: SensorModel, plan: _Plan, rngs: list[np.random.Generator],
                 view: Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]] = dict,
                 rates: tuple[str, ...] = ()) -> None:
        sample_rate_hz, nz = plan.sample_rate_hz, model.noise
        self.model, self.plan, self.view = model, plan, view
        self.q = WhiteAngle(nz.Q_arcsec, sample_rate_hz, rngs[0]) if nz.Q_arcsec > 0 else None
        self.white = WhiteRate(sample_rate_hz, rngs[1])
        self.levels = [e for e in model.effects if EFFECT_KINDS[e.kind].nature == "white_level"]
        self.b = (Flicker(nz.B_dph, sample_rate_hz, rngs[2], default_flicker_tau_hi_s(sample_rate_hz, plan.duration_s))
                  if nz.B_dph > 0 else None)
        self.k = RandomWalk(nz.K_dphsh, sample_rate_hz, rngs[3]) if nz.K_dphsh > 0 else None
        self.noises = [fx.noise_generator(e, sample_rate_hz, rngs[4 + i]) for i, e in enumerate(model.effects)
                       if EFFECT_KINDS[e.kind].nature == "noise"]
        means = [e for e in model.effects if EFFECT_KINDS[e.kind].nature == "mean"]
        self.means = [e for e in means if not _reads_rates(e, rates)]
        self.cross = [e for e in means if _reads_rates(e, rates)]
        self.filters = [fx.BandwidthFilter(e.params, sample_rate_hz) for e in model.effects
                        if EFFECT_KINDS[e.kind].nature == "filter"]
        #: samples before a chunk that mean-rate effects look back on
        self.back = int(math.ceil(max([fx.lookback_s(e) for e in means] + [0.0]) * sample_rate_hz)) + 2

    def rate_dph(self, k0: int, k1: int, t: np.ndarray, all_aux: dict[str, np.ndarray]) -> np.ndarray:
        """The rate (deg/h) of grid samples ``k0:k1`` at times ``t`` (s) with the aux
        channels ``all_aux`` (this axis sees ``view(all_aux)``), no cross terms."""
        return self.finish(self.unfiltered(k0, k1, t, all_aux), k0, k1, t, all_aux)

    def _add_means(self, rate: np.ndarray, effects: list, k0: int, k1: int, t: np.ndarray, aux: dict, kb: int,
                   extra: dict[str, np.ndarray] | None = None) -> None:
        """Add to ``rate`` (deg/h, grid samples ``k0:k1``) the mean-type ``effects``,
        evaluated from grid sample ``kb`` on (their look-back), ``extra`` channels over ``kb:k1``."""
        te, auxe = t, aux
        if kb < k0:
            te, back_aux, _ = self.plan.chunk(kb, k1)
            auxe = self.view(back_aux)
        if extra:
            auxe = {**auxe, **extra}
        for e in effects:
            rate += fx.mean_rate_dph(e, te, auxe, self.plan.sample_rate_hz)[k0 - kb:]

    def finish(self, rate: np.ndarray, k0: int, k1: int, t: np.ndarray, all_aux: dict[str, np.ndarray],
               rates: dict[str, np.ndarray] | None = None, kb: int | None = None) -> np.ndarray:
        """``rate`` (``unfiltered``) with the cross terms (``rates``: the simulated axes'
        unfiltered rate columns over grid samples ``kb:k1``) and then the filters."""
        if self.cross:
            assert rates is not None and kb is not None, "cross terms need the axes' rates"
            rate = rate.copy()
            self._add_means(rate, self.cross, k0, k1, t, self.view(all_aux), kb, rates)
        for f in self.filters:
            rate = f.apply(rate)
        return rate

    def unfiltered(self, k0: int, k1: int, t: np.ndarray, all_aux: dict[str, np.ndarray]) -> np.ndarray:
        """The rate (deg/h) of grid samples ``k0:k1`` before the filters and the cross
        terms."""
        model, nz, n = self.model, self.model.noise, k1 - k0
        aux = self.view(all_aux)
        rate = np.full(n, model.bias_dph)
        if "rot_dps" in aux:
            rate += 3600.0 * aux["rot_dps"]
        level = np.full(n, nz.N_dpsh)
        for e in self.levels:
            level = level + fx.white_level_dpsh(e, t, aux)
        if nz.N_dpsh > 0 or self.levels:
            rate += self.white.generate(n, np.maximum(level, 0.0))
        for gen in (self.q, self.b, self.k, *self.noises):
            if gen is not None:
                rate += gen.generate(n)
        if nz.R_dphh:
            rate += ramp_dph(nz.R_dphh, t - self.plan.t0)
        if self.means:
            self._add_means(rate, self.means, k0, k1, t, aux, max(0, k0 - self.back))
        return rate


def simulated_axes(model: SensorModel, like: Recording | None = None, axes: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The axes a simulation has: the model's [noise.<axis>] tables, else the axes of
    ``like``, else ``axes`` (a scenario's); () for a one-axis run."""
    return model.axes or (like.axes if like is not None else ()) or tuple(axes)


def _axis_parts(model: SensorModel, plan: _Plan, ss: np.random.SeedSequence, axes: tuple[str, ...],
                named: tuple[str, ...], where: str = "model") -> list[_Parts]:
    """One _Parts per axis of ``axes``: its one-axis model, its own child of ``ss``, the
    aux channels it sees (``axis_aux`` among every axis ``named`` by model, input or caller)."""
    parts = []
    for a, child in zip(axes, ss.spawn(len(axes)), strict=True):
        one = model.for_axis(a)
        view = functools.partial(axis_aux, axes=named, name=a)
        _check_aux(one, set(view(plan.src_aux)), a, axes, where)
        parts.append(_Parts(one, plan, [np.random.default_rng(c) for c in child.spawn(4 + len(one.effects))], view,
                            axes))
    return parts


def iter_simulate(model: SensorModel, duration_s: float | None = None, like: Recording | None = None,
                  aux: dict | None = None, seed: int | None = None, aux_t_s=None,
                  chunk_samples: int = CHUNK_SAMPLES, meta_out: dict | None = None,
                  axes: tuple[str, ...] = (), where: str = "model") -> Iterator[Block]:
    """Yield the simulation as Blocks of at most ``chunk_samples`` samples (t_s in s,
    rate_dph in deg/h, aux channels). Infinite when neither a duration, a recording nor
    aux channels bound it. ``meta_out`` (a dict) receives sample_rate_hz and seed.
    Several axes (``simulated_axes``; ``axes`` names them when neither the model nor
    ``like`` does): Blocks with ``axes`` and one rate column per axis. ``where`` names
    the model in error messages (its file); the model is checked against its input when
    the first block is asked for, before anything is simulated."""
    model = validate_model(model, where)
    if seed is not None and not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise FogmonError(f"seed must be a non-negative integer, got {seed!r}")
    plan = _Plan(model, duration_s, like, aux, aux_t_s)
    sim_axes = simulated_axes(model, like, axes)
    ss = np.random.SeedSequence(seed)
    if meta_out is not None:
        meta_out.update(sample_rate_hz=f"{plan.sample_rate_hz:g}", seed=str(ss.entropy))
    if sim_axes:
        named = tuple(dict.fromkeys((*sim_axes, *(like.axes if like is not None else ()), *axes)))
        parts = _axis_parts(model, plan, ss, sim_axes, named, where)
    else:
        _check_aux(model, set(plan.src_aux), where=where)
        parts = [_Parts(model, plan, [np.random.default_rng(s) for s in ss.spawn(4 + len(model.effects))])]
    k0 = 0
    cross = _CrossRates(sim_axes, max(p.back for p in parts)) if any(p.cross for p in parts) else None
    while plan.n is None or k0 < plan.n:
        k1 = k0 + chunk_samples if plan.n is None else min(plan.n, k0 + chunk_samples)
        t, aux_c, present = plan.chunk(k0, k1)
        pre = [p.unfiltered(k0, k1, t, aux_c) for p in parts]
        rates, kb = cross.add(pre, k1) if cross is not None else (None, None)
        done = [p.finish(r, k0, k1, t, aux_c, rates, kb) for p, r in zip(parts, pre, strict=True)]
        rate = np.column_stack(done) if sim_axes else done[0]
        rate[~present] = np.nan
        out_aux = {name: np.where(present, a, np.nan) for name, a in aux_c.items()}
        valid = np.repeat(present[:, None], len(sim_axes), axis=1) if sim_axes else present.copy()
        yield Block(t, rate, valid, out_aux, axes=sim_axes)
        k0 = k1


class _CrossRates:
    """The axes' unfiltered rates of the current chunk and the ``back`` grid samples
    before it, the features of the cross terms (``aux_response`` reading another axis's
    rate column; its look-back for ``d(NAME)/dt``)."""

    def __init__(self, axes: tuple[str, ...], back: int) -> None:
        self.axes, self.back = axes, back
        self.hist = np.zeros((0, len(axes)))

    def add(self, pre: list[np.ndarray], k1: int) -> tuple[dict[str, np.ndarray], int]:
        """(rate columns by name over grid samples kb:k1, kb) with the chunk's rates ``pre``."""
        span = np.vstack([self.hist, np.column_stack(pre)])
        self.hist = span[-self.back:]
        return {f"rate_{a}_dph": span[:, j] for j, a in enumerate(self.axes)}, k1 - len(span)


def present_samples(block: Block) -> np.ndarray:
    """The samples of a simulated block that exist (every axis of a sample shares its
    presence: a gap of the input is a gap of every axis)."""
    return block.valid if not block.axes else np.all(block.valid, axis=1)


def simulate(model: SensorModel, duration_s: float | None = None, like: Recording | None = None,
             aux: dict | None = None, seed: int | None = None, aux_t_s=None,
             meta: dict | None = None, axes: tuple[str, ...] = ()) -> Recording:
    """The whole simulation as a Recording (valid samples only; ``meta`` gets
    sample_rate_hz and seed added). Same numbers as concatenating ``iter_simulate``;
    several axes as there (a Recording with ``axes``)."""
    if like is None and not aux and duration_s is None:
        raise FogmonError("simulate needs a duration, a recording to simulate like, or aux channels")
    info: dict = {}
    ts, rs, auxs = [], [], {}  # type: ignore[var-annotated]
    for blk in iter_simulate(model, duration_s, like, aux, seed, aux_t_s, meta_out=info, axes=axes):
        v = present_samples(blk)
        ts.append(blk.t_s[v])
        rs.append(blk.rate_dph[v])
        for name, a in blk.aux.items():
            auxs.setdefault(name, []).append(a[v])
    full_meta = {**info, **(meta or {})}
    full_meta["sample_rate_hz"] = info["sample_rate_hz"]
    full_meta["seed"] = info["seed"]
    return Recording(np.concatenate(ts), np.concatenate(rs),
                     {k: np.concatenate(v) for k, v in auxs.items()}, full_meta,
                     axes=simulated_axes(model, like, axes))
