"""What runs on a Dask worker for `fogmon batch`: checking a recording, the motion pass
of a split recording, one chunk through the streaming pipeline of `fogmon replay`
(fogmon.pipeline.run_pipeline, the same engine, fits and motion gate), and explain with
a model. Every task takes picklable values (the options as frozen dataclasses: how to
read a recording, SourceOptions; how to analyse it, PipelineConfig) and returns them; a
failure is returned as a one-line ``error`` (the recording is named by the caller,
parameters as `name`: fogmon.errors.render_names), never raised."""
from __future__ import annotations

import contextlib
import os
import traceback
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from fogmon.block import Block
from fogmon.errors import FogmonError
from fogmon.fleet.identity import source_meta
from fogmon.pipeline import PipelineConfig, window_and_hop
from fogmon.pipeline.accel import ACCEL_CHANNEL
from fogmon.sinks.base import ACCEL_COEFFICIENTS, COEFFICIENTS, Sink
from fogmon.sources.base import OfflineSource
from fogmon.sources.options import SourceOptions

if TYPE_CHECKING:
    from fogmon.explain.options import Options

#: the PipelineConfig fields of `fogmon replay` the tasks use (the others keep their defaults)
ANALYSIS_OPTIONS = ("window_s", "hop_s", "taus", "raw_rate", "keep_motion", "accels")


def _analysis(config: PipelineConfig, **changes) -> PipelineConfig:
    """A PipelineConfig of ``config``'s ANALYSIS_OPTIONS only, with ``changes``."""
    return PipelineConfig(**{**{k: getattr(config, k) for k in ANALYSIS_OPTIONS}, **changes})


def _failure(e: BaseException) -> str:
    if isinstance(e, FogmonError):
        return e.message
    last = traceback.extract_tb(e.__traceback__)[-1] if e.__traceback__ else None
    where = f" ({os.path.basename(last.filename)}:{last.lineno})" if last else ""
    return f"{type(e).__name__}: {e}{where}".splitlines()[0]


def _open(path: str, source: SourceOptions):
    from fogmon.sources.open import open_replay_source
    return open_replay_source(path, source)


def input_kind(path: str) -> str:
    """A short name of the input's format."""
    if os.path.isdir(path):
        return "archive"
    ext = os.path.splitext(path)[1].lower()
    return {".csv": "csv", ".parquet": "parquet"}.get(ext, "capture" if os.path.exists(path + ".json") else ext[1:])


@dataclass
class Plan:
    """A checked recording: sample rate (Hz), samples on its grid, window and hop (s,
    as `fogmon replay` chooses them), its axis (of a one-axis source) or ``axes`` (of a
    source of several axes, each analysed as a recording of its own), the metadata that
    may name its gyro (fleet.identity); or ``error``."""

    path: str
    sample_rate_hz: float = float("nan")
    n_samples: int = 0
    window_s: float = float("nan")
    hop_s: float = float("nan")
    axis: str = "-"
    axes: tuple[str, ...] = ()
    kind: str = ""
    error: str = ""
    meta: dict = field(default_factory=dict)


def check(path: str, source: SourceOptions, config: PipelineConfig) -> Plan:
    """Open ``path`` as `fogmon replay` would with ``source`` (every row checked) and
    choose its window as ``config`` asks."""
    plan = Plan(path, kind=input_kind(path))
    try:
        src = _open(path, source)
        try:
            n = src.n_samples
            if n is None:
                raise FogmonError(f"{path}: an endless source (a sensor model) has no end to analyse")
            plan.sample_rate_hz, plan.n_samples = float(src.sample_rate_hz), int(n)
            plan.window_s, plan.hop_s = window_and_hop(_analysis(config), plan.sample_rate_hz, plan.n_samples, path)
            plan.axis, plan.axes = _axis(src), tuple(src.axes)
            plan.meta = source_meta(src)
        finally:
            src.close()
    except Exception as e:
        plan.error = _failure(e)
    return plan


def _axis(src) -> str:
    """The gyro axis the source names (a KVH capture's decoder option, a log's ``axis``
    metadata), else '-'."""
    opts = getattr(src, "_options", None) or {}
    meta = getattr(src, "meta", None) or {}
    return str(opts.get("axis") or meta.get("axis") or "-")


def _blocks(source, axis: str):
    """The source's blocks, or their one-axis view of ``axis`` ("": as they are)."""
    return (b.axis(axis) for b in source.blocks()) if axis else source.blocks()


class _ChunkSource(OfflineSource):
    """Samples ``first`` .. ``stop`` - 1 (grid indices) of axis ``axis`` ("": a one-axis
    source) of ``source``, read from its start; samples in ``masked`` runs [(a, b), ...]
    made invalid (the motion gate's decisions from the motion pass). Counts, in ``own`` =
    (a, b), the samples and the invalid ones (before the mask), as the pipeline's summary
    does."""

    def __init__(self, source, first: int, stop: int, own: tuple[int, int], masked=(), axis: str = "") -> None:
        self._src, self.first, self.stop, self.own, self.axis = source, first, stop, own, axis
        self.sample_rate_hz, self.name = source.sample_rate_hz, source.name
        self.aux_names = getattr(source, "aux_names", ())
        self.axes = source.axes if not axis else ()
        self.n_samples = stop - first
        self._masked = np.asarray(masked, dtype=np.int64).reshape(-1, 2)
        self.t0_s: float | None = None   # time of the recording's first sample (s)
        self.own_samples = self.own_invalid = 0
        self.own_accel_invalid: dict[str, int] = {}   # accelerometer aux channel -> NaN samples it owns

    @property
    def counters(self) -> dict:
        return self._src.counters

    def blocks(self):
        pos = 0
        for b in _blocks(self._src, self.axis):
            if self.t0_s is None and len(b):
                self.t0_s = float(b.t_s[0])
            a, z = max(self.first - pos, 0), min(self.stop - pos, len(b))
            if a < z:
                part = b if (a, z) == (0, len(b)) else b.slice(a, z)
                lo, hi = max(self.own[0] - pos - a, 0), min(self.own[1] - pos - a, len(part))
                if lo < hi:
                    self.own_samples += hi - lo
                    self.own_invalid += int(hi - lo - np.count_nonzero(part.valid[lo:hi]))
                    for k, v in part.aux.items():
                        if ACCEL_CHANNEL.fullmatch(k):
                            self.own_accel_invalid[k] = (self.own_accel_invalid.get(k, 0)
                                                         + int(np.count_nonzero(~np.isfinite(v[lo:hi]))))
                yield self._mask(part, pos + a)
            pos += len(b)
            if pos >= self.stop:
                break

    def _mask(self, b: Block, at: int) -> Block:
        m = self._masked
        m = m[(m[:, 1] > at) & (m[:, 0] < at + len(b))]
        if not len(m):
            return b
        valid = b.valid.copy()
        moved = np.zeros(len(b), dtype=bool)
        for a, z in m - at:
            moved[max(a, 0):max(z, 0)] = True
        valid[moved] = False   # and the accelerometers that follow the gate (fogmon.pipeline.accel)
        aux = {k: np.where(moved, np.nan, v) if ACCEL_CHANNEL.fullmatch(k) else v for k, v in b.aux.items()}
        return Block(b.t_s, b.rate_dph, valid, aux, b.events, b.axes)

    def close(self) -> None:
        self._src.close()


def _fit_columns(fit, names) -> dict[str, np.ndarray]:
    """Coefficients ``names`` of a DADEV fit as columns: value, _lo, _hi, identifiable_."""
    cols = {}
    for c in names:
        co = getattr(fit, c)
        cols[c], cols[f"{c}_lo"], cols[f"{c}_hi"] = (np.asarray(x, np.float64) for x in (co.value, co.lo, co.hi))
        cols[f"identifiable_{c}"] = np.asarray(co.identifiable, bool)
    return cols


@dataclass
class _Windows:
    """The windows of one sensor axis: end indices, ADEV rows, fit columns."""

    ends: list[np.ndarray] = field(default_factory=list)
    adev: list[np.ndarray] = field(default_factory=list)
    fits: list[dict[str, np.ndarray]] = field(default_factory=list)

    def add(self, dadev, cols: dict[str, np.ndarray]) -> None:
        self.ends.append(np.asarray(dadev.end_index, np.int64))
        self.adev.append(np.asarray(dadev.adev_dph, np.float64))
        self.fits.append(cols)

    def owned(self, first: int, keep) -> dict:
        """The windows ``keep`` (a function of their grid end indices) chooses, as columns
        (``t_end_s`` left to the caller: ``ends`` is the grid index from ``first``)."""
        if not self.ends:
            return {}
        ends = first + np.concatenate(self.ends)
        k = keep(ends)
        out = {"ends": ends[k], "adev": np.concatenate(self.adev)[k]}
        for name in self.fits[0]:
            out[name] = np.concatenate([f[name] for f in self.fits])[k]
        return out


class _Collect(Sink):
    """Keeps the windows the pipeline completes (end index, ADEV, fit), the
    accelerometers' windows (``accels``: name -> _Windows) and the summary."""

    def __init__(self) -> None:
        self.gyro = _Windows()
        self.accels: dict[str, _Windows] = {}
        self.tau_s: np.ndarray | None = None
        self.summary = None

    def start(self, info) -> None:
        self.tau_s = np.asarray(info.tau_s)

    def frames(self, dadev, fit, t_end_s, axis: str = "") -> None:
        self.gyro.add(dadev, _fit_columns(fit, COEFFICIENTS))

    def accel_frames(self, dadev, fit, t_end_s, accel: str) -> None:
        self.accels.setdefault(accel, _Windows()).add(dadev, _fit_columns(fit, ACCEL_COEFFICIENTS))

    def finish(self, summary) -> None:
        self.summary = summary


@dataclass
class ChunkResult:
    """The windows a chunk owns (``windows``: column -> array; ``tau_s`` of the ADEV
    columns) and, for the last chunk, the recording's facts (``record``); or ``error``."""

    path: str
    index: int
    windows: dict = field(default_factory=dict)
    tau_s: np.ndarray | None = None
    own_samples: int = 0
    own_invalid: int = 0
    record: dict = field(default_factory=dict)
    error: str = ""
    accel_windows: dict[str, dict] = field(default_factory=dict)   # accelerometer -> its windows, as ``windows``
    accel_invalid: dict[str, int] = field(default_factory=dict)    # accelerometer -> NaN samples the chunk owns
    accel_records: dict[str, dict] = field(default_factory=dict)   # last chunk: accelerometer -> its whole-record fit


def run_chunk(plan: Plan, chunk, source: SourceOptions, config: PipelineConfig, masked=None,
              axis: str = "") -> ChunkResult:
    """Chunk ``chunk`` (fogmon.fleet.chunks.Chunk) of axis ``axis`` ("": a one-axis
    recording) of the recording through ``run_pipeline`` with the analysis of ``config``
    and the window and hop of ``plan``. ``masked``: the motion pass's runs when the recording is split (the
    pipeline's own gate is then off: it would start afresh in each chunk), None to let
    the pipeline's gate run (one chunk)."""
    from fogmon.pipeline import run_pipeline

    out = ChunkResult(plan.path, chunk.index)
    if isinstance(masked, MotionResult):      # the motion pass's result, handed on by Dask
        if masked.error:
            out.error = masked.error
            return out
        masked = masked.runs
    try:
        src = _ChunkSource(_open(plan.path, source), chunk.feed_first, chunk.feed_stop,
                           (chunk.own_first, chunk.own_stop), masked if masked is not None else (), axis)
        accels = config.accels   # an axis's task analyses that axis's accelerometer (as replay's gate pairs them)
        if axis:
            accels = (axis,) if accels is None or axis in accels else ()
        run = _analysis(config, window_s=plan.window_s, hop_s=plan.hop_s,
                        keep_motion=config.keep_motion or masked is not None, accels=accels)
        col = _Collect()
        summary = run_pipeline(src, run, [col])
        out.own_samples, out.own_invalid = src.own_samples, src.own_invalid
        out.tau_s = col.tau_s
        hop = int(round(plan.hop_s * plan.sample_rate_hz))
        w = int(round(plan.window_s * plan.sample_rate_hz))

        def keep(ends: np.ndarray) -> np.ndarray:
            k = (ends - (w - 1)) // hop
            return (k >= chunk.k_first) & (k < chunk.k_stop)

        def timed(cols: dict) -> dict:
            return {"t_end_s": src.t0_s + cols.pop("ends") / plan.sample_rate_hz, **cols} if cols else {}

        out.windows = timed(col.gyro.owned(chunk.feed_first, keep))
        out.accel_windows = {a: timed(x.owned(chunk.feed_first, keep)) for a, x in col.accels.items()}
        names = {k: m.group(1) for k in src.own_accel_invalid if (m := ACCEL_CHANNEL.fullmatch(k))}
        out.accel_invalid = {names[k]: n for k, n in src.own_accel_invalid.items()
                             if accels is None or names[k] in accels}
        if chunk.last:
            out.record = _record_facts(summary, src.t0_s)
            out.accel_records = {a: _fit_facts(x.overall_fit, ACCEL_COEFFICIENTS) | {"fit_first_s": x.overall_first_s}
                                 for a, x in summary.accels.items()}
    except Exception as e:
        out.error = _failure(e)
    return out


def _record_facts(summary, t0_s: float | None) -> dict:
    """The recording's row from the last chunk's summary: its span, the source's counters
    (read from the recording's start) and the whole-record fit."""
    rec = {"t_first_s": t0_s, "t_last_s": summary.t_last_s,
           "gaps": int(summary.counters.get("seq_gaps", 0)),
           "motion_samples_excluded": int(summary.motion_samples), "fit_first_s": summary.overall_first_s}
    return rec | _fit_facts(summary.overall_fit, COEFFICIENTS)


def _fit_facts(fit, names) -> dict:
    """A whole-record fit's coefficients ``names`` (value, _lo, _hi, identifiable_; NaN
    and False without a fit)."""
    rec: dict = {}
    for c in names:
        co = getattr(fit, c, None)
        rec[c] = float(co.value) if co is not None else float("nan")
        rec[f"{c}_lo"] = float(co.lo) if co is not None else float("nan")
        rec[f"{c}_hi"] = float(co.hi) if co is not None else float("nan")
        rec[f"identifiable_{c}"] = bool(co.identifiable) if co is not None else False
    return rec


@dataclass
class MotionResult:
    """The motion gate's decisions over a whole recording: runs [(a, b)] of grid indices
    it made invalid, the valid samples it excluded; or ``error``."""

    path: str
    runs: np.ndarray | None = None
    samples_excluded: int = 0
    error: str = ""


def motion_pass(plan: Plan, source: SourceOptions, config: PipelineConfig, axis: str = "") -> MotionResult:
    """Run the pipeline's platform-motion gate (fogmon.motion_gate.MotionGate) over the whole
    recording (its axis ``axis``; "": a one-axis recording), block by block as `fogmon
    replay` does (on rate_dph - 3600 x rot_dps unless ``config.raw_rate``), and record
    which samples it made invalid, so that chunks analysed separately see exactly the
    same samples."""
    from fogmon.motion_gate import MotionGate

    out = MotionResult(plan.path)
    try:
        src = _open(plan.path, source)
        gate = MotionGate(plan.sample_rate_hz)
        use_ref = None
        pos = 0                                 # grid index of the next sample released
        runs: list[tuple[int, int]] = []

        def released(moved: np.ndarray) -> None:
            nonlocal pos
            masked = np.flatnonzero(moved)
            if len(masked):
                cuts = np.flatnonzero(np.diff(masked) > 1)
                starts = np.concatenate([[masked[0]], masked[cuts + 1]])
                stops = np.concatenate([masked[cuts], [masked[-1]]]) + 1
                runs.extend(zip((pos + starts).tolist(), (pos + stops).tolist(), strict=True))
            pos += len(moved)

        try:
            for b in _blocks(src, axis):
                if not len(b):
                    continue
                if use_ref is None:
                    use_ref = "rot_dps" in b.aux and not config.raw_rate
                y = b.error_rate_dph if use_ref else b.rate_dph
                released(gate.push(b.t_s, y, b.valid & np.isfinite(y)).moved)
            released(gate.flush().moved)
        finally:
            src.close()
        out.runs = np.asarray(runs, dtype=np.int64).reshape(-1, 2)
        out.samples_excluded = int(gate.samples_excluded)
    except Exception as e:
        out.error = _failure(e)
    return out


def explain_recording(path: str, model_path: str, source: SourceOptions, config: PipelineConfig,
                      axis: str = "", options: Options | None = None) -> dict:
    """`fogmon explain` of the recording ``path`` against the sensor model ``model_path``
    with explain's ``options`` (None: its defaults), of axis ``axis`` with the model's
    axis ``axis`` ("": a one-axis recording), platform motion left out unless
    ``config.keep_motion``: the score before and after the effects it found, and their
    kinds (comma-separated); or ``explain_error``."""
    from fogmon.explain import report
    from fogmon.explain.explainer import explain, without_motion
    from fogmon.explain.options import Options
    from fogmon.formats.recording import recording_from_arrays
    from fogmon.formats.replay_log import read_replay_log
    from fogmon.sim.model import load_model

    try:
        if input_kind(path) in ("csv", "parquet"):
            rec = read_replay_log(path)
            rec = rec.for_axis(axis) if axis else rec
        else:  # a capture, CAN log or archive: its valid samples, as `fogmon convert` writes them
            src = _open(path, source)
            parts = [b for b in _blocks(src, axis) if len(b)]
            t = np.concatenate([b.t_s[b.valid] for b in parts])
            rec = recording_from_arrays(t, np.concatenate([b.rate_dph[b.valid] for b in parts]),
                                        {k: np.concatenate([b.aux[k][b.valid] for b in parts]) for k in parts[0].aux},
                                        {"sample_rate_hz": f"{src.sample_rate_hz:.12g}"})
        if not config.keep_motion:
            rec, _ = without_motion(rec)
        model = load_model(model_path)
        with _cluster_replicates() as mapper:
            res = explain(rec, model.for_axis(axis) if axis else model, Options() if options is None else options,
                          mapper=mapper)
        rep = report.build_report(res, path, model_path)
        return {"explain_score_before": float(rep["score_before"]), "explain_score_after": float(rep["score_after"]),
                "explain_effects": ",".join(e["kind"] for e in rep["effects"]), "explain_error": ""}
    except Exception as e:
        return {"explain_score_before": float("nan"), "explain_score_after": float("nan"), "explain_effects": "",
                "explain_error": _failure(e)}


@contextlib.contextmanager
def _cluster_replicates():
    """explain's bootstrap replicates as tasks of the Dask cluster this task runs on (the
    task leaves its worker's thread pool meanwhile, so the replicates can run there too):
    one long recording's bootstrap is spread over the cluster. None outside a Dask worker."""
    from distributed import get_worker, worker_client

    try:
        get_worker()
    except ValueError:
        yield None
        return
    with worker_client() as client:
        yield _DaskReplicates(client)


class _DaskReplicates:
    """A ``fogmon.explain.bootstrap.Mapper`` on a Dask client: the replicas and the
    function scattered once, one task per replicate seed."""

    def __init__(self, client):
        self.client = client

    def __call__(self, fn, replicas, seeds):
        shared = self.client.scatter((replicas, fn), broadcast=True, hash=False)
        return self.client.gather(self.client.map(_replicate, list(seeds), shared=shared, pure=False))


def _replicate(seed: int, shared: tuple):
    replicas, fn = shared
    return fn(replicas.draw(seed))
