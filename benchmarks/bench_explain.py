"""Runtime of `fogmon explain` (issue 33.2): 1e6 and 1e7 samples at 100 Hz and a
three-axis record of 2 h at 100 Hz with 3 aux channels (the MWD scenario of fogmon.sim:
temp_c, rot_dps, vib_g), each beside allantools' overlapping ADEV (octave taus) of the
same data measured in the same run, so the ratio travels across machines.

For each case: the wall time of the whole analysis (bootstrap, map, candidate
selection, map again), its CPU time (this process and its bootstrap workers), the peak
memory (largest resident set of the explaining process and of its largest worker;
each case runs in a process of its own), what was found, and the
targets on a 2-core machine: 1e6 <= 10 s, 1e7 <= 90 s, the three-axis record <= 180 s,
memory < 2 GB. The 1e6 and 1e7 records hold a concealed periodic term (0.3 of the
per-sample noise std, period 777 s: found and fitted), the three-axis record is a null
explained against its own model. `--batch` also runs the 1e7 record through `fogmon
batch --model`'s explain task on a local Dask cluster of 2 workers, with the bootstrap
replicates as tasks of the cluster and without (the whole explain in one task), and
prints the speed-up.

Run:  python benchmarks/bench_explain.py [--only 1e6 1e7 3axes] [--batch]
"""
from __future__ import annotations

import argparse
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import allantools
import numpy as np

from fogmon.explain.axes import explain_axes
from fogmon.explain.explainer import explain
from fogmon.explain.options import Options
from fogmon.formats.recording import recording_from_arrays
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.scenarios import MwdParams, mwd_run
from fogmon.sim.simulate import simulate

FS = 100.0
NOISE = Noise(Q_arcsec=0.05, N_dpsh=0.01, B_dph=0.01)
TARGET_S = {"1e6": 10.0, "1e7": 90.0, "3axes": 180.0}
MEMORY_TARGET_MB = 2048.0


def _sigma() -> float:
    return math.sqrt((60 * NOISE.N_dpsh) ** 2 * FS + 2 * (NOISE.Q_arcsec * FS) ** 2)


def one_axis(n: int):
    """(recording, model): n samples with a concealed periodic term, the model without it."""
    eff = [Effect("periodic", {"period_s": 777.0, "amplitude_dph": 0.3 * _sigma(), "phase_rad": 0.0})]
    rec = simulate(SensorModel(FS, 0.5, NOISE, eff), duration_s=n / FS, seed=2)
    return rec, SensorModel(FS, 0.5, NOISE, [])


def three_axes():
    """(recording, model): 2 h at 100 Hz on axes x, y, z along one MWD run's aux channels."""
    model = SensorModel(FS, 0.5, NOISE, [], axis_noise={a: NOISE for a in "xyz"})
    sc = mwd_run(MwdParams(duration_s=2 * 3600.0), seed=3)
    aux = {k: sc.aux[k] for k in ("temp_c", "rot_dps", "vib_g")}
    first = simulate(model.for_axis("x"), seed=4, aux=aux, aux_t_s=sc.t_s, duration_s=2 * 3600.0)
    rates = [first.rate_dph] + [simulate(model.for_axis(a), like=first, seed=5 + i).rate_dph
                                for i, a in enumerate("yz")]
    return recording_from_arrays(first.t_s, np.column_stack(rates), first.aux, first.meta, axes=("x", "y", "z")), model


def _cpu_s() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _peak_mb() -> tuple[float, float]:
    """Largest resident set (MB) of this process and of its largest bootstrap worker (a
    forked worker's set counts the pages it shares with this process)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_maxrss / 1024.0, kids.ru_maxrss / 1024.0


def reference(rates: np.ndarray) -> float:
    """Wall time (s) of allantools' oadev (octave taus) of every rate column."""
    t0 = time.perf_counter()
    for r in np.atleast_2d(rates.T):
        allantools.oadev(np.asarray(r, dtype=float), rate=FS, data_type="freq", taus="octave")
    return time.perf_counter() - t0


def run(case: str) -> bool:
    rec, model = three_axes() if case == "3axes" else one_axis(int(float(case)))
    ref = reference(rec.rate_dph)
    t0, c0 = time.perf_counter(), _cpu_s()
    if case == "3axes":
        res = explain_axes(rec, model, Options())
        found = "; ".join(f"{a}: {', '.join(x.cand.kind for x in r.accepted) or 'none'}"
                          for a, r in res.results.items())
        score = f"{res.score_before:.2f} -> {res.score_after:.2f}"
    else:
        r1 = explain(rec, model, Options())
        found = ", ".join(x.cand.kind for x in r1.accepted) or "none"
        score = f"{r1.before.score.value:.2f} -> {r1.after.score.value:.2f}"
    wall, cpu, (mem, worker) = time.perf_counter() - t0, _cpu_s() - c0, _peak_mb()
    ok = wall <= TARGET_S[case] and max(mem, worker) < MEMORY_TARGET_MB
    print(f"{case:6s} {rec.rate_dph.size:9d} samples: explain {wall:6.1f} s wall ({cpu:6.1f} CPU s), "
          f"allantools oadev {ref:6.2f} s, ratio {wall / ref:6.1f}; peak memory {mem:6.0f} MB (largest worker "
          f"{worker:4.0f} MB); found: {found}; "
          f"score {score}; {'PASS' if ok else 'FAIL'} (<= {TARGET_S[case]:g} s, < {MEMORY_TARGET_MB:g} MB)",
          flush=True)
    return ok


def batch_speedup() -> None:
    """The 1e7 record's explain task of `fogmon batch --model` on 2 Dask workers, with the
    bootstrap replicates as cluster tasks and with the whole explain in one task."""
    import logging

    from distributed import Client, LocalCluster

    from fogmon.formats.replay_log import write_replay_log
    from fogmon.pipeline import PipelineConfig
    from fogmon.sim.model import save_model
    from fogmon.sources.options import SourceOptions

    rec, model = one_axis(10_000_000)
    with tempfile.TemporaryDirectory() as d:
        path, model_path = Path(d) / "long.csv", Path(d) / "model.toml"
        write_replay_log(str(path), rec.t_s, rec.rate_dph, rec.aux, rec.meta)
        save_model(model, str(model_path))
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                          silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
            times = {}
            for label, split in (("replicates as tasks", True), ("one task", False)):
                t0 = time.perf_counter()
                row = client.submit(_explain_task, str(path), str(model_path), SourceOptions(), PipelineConfig(),
                                    split, pure=False).result()
                times[label] = time.perf_counter() - t0
                print(f"batch explain task, {label}: {times[label]:.1f} s wall; score {row['explain_score_before']:.2f}"
                      f" -> {row['explain_score_after']:.2f}, effects {row['explain_effects'] or 'none'} "
                      f"{row['explain_error']}", flush=True)
    print(f"speed-up of the replicates as cluster tasks: {times['one task'] / times['replicates as tasks']:.2f}x "
          f"on 2 workers")


def _explain_task(path: str, model_path: str, source, config, split: bool) -> dict:
    """tasks.explain_recording, its replicates as cluster tasks or (``split`` False) in this task."""
    import contextlib

    from fogmon.fleet import tasks

    if split:
        return tasks.explain_recording(path, model_path, source, config)
    original = tasks._cluster_replicates
    tasks._cluster_replicates = contextlib.nullcontext  # type: ignore[assignment]
    try:
        return tasks.explain_recording(path, model_path, source, config)
    finally:
        tasks._cluster_replicates = original


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=tuple(TARGET_S), default=list(TARGET_S))
    ap.add_argument("--batch", action="store_true", help="also measure `fogmon batch --model` on 2 Dask workers")
    a = ap.parse_args()
    if not os.environ.get("BENCH_EXPLAIN_CASE"):
        print(f"fogmon explain runtime ({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f})", flush=True)
    if len(a.only) > 1:  # one process per case: each case's own peak memory
        env = {**os.environ, "BENCH_EXPLAIN_CASE": "1"}
        ok = all([subprocess.run([sys.executable, __file__, "--only", c], check=False, env=env).returncode == 0
                  for c in a.only])
    else:
        ok = run(a.only[0])
    if a.batch:
        batch_speedup()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
