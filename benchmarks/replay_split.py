"""Driver for bench_pipeline.py: one `fogmon replay` of a replay log into an .rrd in this
process, run as the fogmon program runs it (``fogmon.startup``: the garbage collector
paused while it loads), in CPU seconds. Prints one ``key=value`` line per figure.

    python benchmarks/replay_split.py REPLAY_LOG RRD [--first-sample]

The split: import, compile (numba kernels compiled or loaded from the cache, done up front
on tiny inputs with the run's types: the engine in both modes, oadev and a fit; a kernel
first needed later is compiled inside its phase), read (the source's block iterator),
engine (StreamingDadev.push, the whole-run oadev), fits (fit_noise; ``fit_cov``: its part
computing the cross-tau covariance matrices, once per tau grid and process), sinks (the
sinks' methods, Rerun's import in the first) and the rest, from the first import on;
``first_read``: CPU s from the first import to the first block read from the source
(compile included, which the plain command does after it).

``--first-sample``: the command in the program's own order, nothing done up front or timed
but ``first_sample``, the CPU s of the process (interpreter start-up included) until the
first block has been handed to every sink (Rerun imported, the .rrd opened, its
blueprint and the first samples sent; the numba kernels are loaded after, when the first
block is analysed), and ``total``, the whole run's.
"""
from __future__ import annotations

import functools
import sys
import time

T0 = time.process_time()
from fogmon import startup  # noqa: E402

startup.own_process()
with startup.loading():      # the imports, as fogmon.cli.main's
    import numpy as np

    import fogmon.cli
    import fogmon.davar.batch
    import fogmon.davar.fit
    import fogmon.davar.streaming
    import fogmon.pipeline
    import fogmon.sinks.console
    import fogmon.sinks.rerun.sink
    import fogmon.sources.files.capture
    import fogmon.sources.files.replay_log

SPENT: dict[str, float] = {}
FIRST: list[float] = []


def timed(key, fn):
    @functools.wraps(fn)
    def wrapper(*a, **kw):
        t = time.process_time()
        try:
            return fn(*a, **kw)
        finally:
            SPENT[key] = SPENT.get(key, 0.0) + time.process_time() - t
    return wrapper


def timed_iter(fn):
    @functools.wraps(fn)
    def wrapper(*a, **kw):
        it = fn(*a, **kw)
        while True:
            t = time.process_time()
            try:
                item = next(it)
            except StopIteration:
                return
            finally:
                SPENT["read"] = SPENT.get("read", 0.0) + time.process_time() - t
            if not FIRST:
                FIRST.append(time.process_time())
            yield item
    return wrapper


def first_delivery(fn):
    @functools.wraps(fn)
    def wrapper(*a, **kw):
        out = fn(*a, **kw)
        if not FIRST:
            FIRST.append(time.process_time())
        return out
    return wrapper


def replay(log: str, rrd: str) -> int:
    return fogmon.cli.main(["replay", log, "--rrd", rrd, "--no-progress", "--quiet"])


def first_sample(log: str, rrd: str) -> int:
    P = fogmon.pipeline.Pipeline
    P._deliver = first_delivery(P._deliver)
    rc = replay(log, rrd)
    print(f"rc={rc}")
    print(f"first_sample={FIRST[0] if FIRST else float('nan'):.3f}")
    print(f"total={time.process_time():.3f}")
    return 0


def split(log: str, rrd: str) -> int:
    t_import = time.process_time() - T0
    t = time.process_time()
    rng = np.random.default_rng(0)
    with startup.loading():
        for hop in (1.0, 64.0):
            fogmon.davar.streaming.StreamingDadev(1.0, 256.0, hop_s=hop).push(rng.normal(size=1000))
        fogmon.davar.fit.fit_noise(fogmon.davar.batch.oadev(rng.normal(size=1000), 1.0))
    t_compile = time.process_time() - t
    S = fogmon.davar.streaming.StreamingDadev
    S.push = timed("engine", S.push)
    fogmon.davar.batch.oadev = timed("engine", fogmon.davar.batch.oadev)
    fogmon.davar.fit.fit_noise = timed("fits", fogmon.davar.fit.fit_noise)
    fogmon.davar.fit.covariance_matrices = timed("fit_cov", fogmon.davar.fit.covariance_matrices)
    for mod in (fogmon.sinks.console, fogmon.sinks.rerun.sink):
        for cls in vars(mod).values():
            if isinstance(cls, type) and cls.__module__ == mod.__name__:
                for name in ("start", "block", "frames", "events", "source_counters", "rotate", "finish"):
                    if name in vars(cls):
                        setattr(cls, name, timed("sinks", vars(cls)[name]))
    for mod in (fogmon.sources.files.replay_log, fogmon.sources.files.capture):
        for cls in vars(mod).values():
            if isinstance(cls, type) and cls.__module__ == mod.__name__ and "blocks" in vars(cls):
                cls.blocks = timed_iter(cls.blocks)
    t = time.process_time()
    rc = replay(log, rrd)
    run = time.process_time() - t
    total = time.process_time() - T0
    print(f"rc={rc}")
    print(f"import={t_import:.3f}")
    print(f"compile={t_compile:.3f}")
    for k in ("read", "engine", "fits", "sinks"):
        print(f"{k}={SPENT.get(k, 0.0):.3f}")
    print(f"fit_cov={SPENT.get('fit_cov', 0.0):.3f}")
    print(f"other={run - sum(v for k, v in SPENT.items() if k != 'fit_cov'):.3f}")
    print(f"first_read={(FIRST[0] if FIRST else total) - T0:.3f}")
    print(f"total={total:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(first_sample(*sys.argv[1:3]) if "--first-sample" in sys.argv[3:] else split(*sys.argv[1:3]))
