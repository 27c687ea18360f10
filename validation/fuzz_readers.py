"""Fuzz every file reader with mutated copies of the public files (issue 32.4).

For each format, N inputs (default 1000) are made from a public file of
tests/data/public by a seeded generator: bit flips (1-16 bits), a truncation, an
insertion of 1-64 random bytes, or two of these. Each input is read the way the commands
read it, in a worker process: ``fogmon.sources.open.file_info`` (``fogmon info``) and
``open_replay_source`` with every block iterated (``fogmon replay``'s reading). An
input passes when it reads or ends in a FogmonError (one line); it fails as a
``traceback`` (any other exception) or a ``hang`` (no answer within ``--timeout-s``: the
worker is killed and restarted). A library that tries to allocate beyond the worker's
address-space limit (``--max-gb``) from a corrupt length field ends in a one-line error
too; such inputs are counted as ``memory``. What the reading printed on file descriptors 1 and 2
is counted as ``stray`` output. Prints one line per format and PASS only with 0
tracebacks and 0 hangs.

    python validation/fuzz_readers.py [--n 1000] [--seed 1] [--timeout-s 60] [--only ulog,las]
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import queue
import random
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field

HERE = os.path.dirname(os.path.abspath(__file__))
PUBLIC = os.path.join(HERE, "..", "tests", "data", "public")
DBC = os.path.join(PUBLIC, "can", "canmod-gps.dbc")
CAN = {"dbc": DBC, "can_rate": "AngularRateZ"}


@dataclass(frozen=True)
class Format:
    """A format: the public file mutated (relative to tests/data/public; ``None``: made
    by ``make``), the suffix of the inputs and the SourceOptions fields to read them."""

    name: str
    base: str | None
    suffix: str
    options: dict = field(default_factory=dict)


FORMATS = [
    Format("ulog", "ulog/sample_bench_8s.ulg", ".ulg", {"axis": "z"}),
    Format("ros1", "ros1/jackal_imu_50hz_20s.bag", ".bag", {"axis": "z"}),
    Format("mcap", "ros2/topics_and_services.mcap", ".mcap"),
    Format("mdf4", "mdf/canmod_imu_decoded_8s.mf4", ".mf4", {"channel": "AngularRateZ"}),
    Format("las", "las/etim_seconds.las", ".las", {"channel": "BFR1", "rate_unit": "deg/s"}),
    Format("las-clock", "las/time_hhmmss_date.las", ".las", {"channel": "ARC_GR_UNC_RT", "rate_unit": "deg/s"}),
    Format("can-asc", "can/canmod_imu_8s.asc", ".asc", CAN),
    Format("can-blf", "can/canmod_imu_8s.blf", ".blf", CAN),
    Format("can-trc", "can/canmod_imu_8s.trc", ".trc", CAN),
    Format("can-log", "can/canmod_imu_8s.log", ".log", CAN),
    Format("can-csv", "can/canmod_imu_8s.csv", ".csv", CAN),
    Format("can-mf4", "can/canmod_imu_8s.mf4", ".mf4", CAN),
    Format("replay-csv", None, ".csv"),
    Format("parquet", None, ".parquet"),
]


def _made(fmt: Format, folder: str) -> bytes:
    """The base bytes of a format made here (a replay log of the ULog's z gyro, as CSV or
    Parquet)."""
    from fogmon.formats.replay_log import write_replay_log
    from fogmon.sources.open import read_recording
    from fogmon.sources.options import SourceOptions
    rec = read_recording(os.path.join(PUBLIC, "ulog", "sample_bench_8s.ulg"), SourceOptions(axis="z"))
    out = os.path.join(folder, "base" + fmt.suffix)
    if fmt.suffix == ".csv":
        write_replay_log(out, rec.t_s[:400], rec.rate_dph[:400], meta={"sample_rate_hz": rec.meta["sample_rate_hz"]})
    else:
        import pyarrow.parquet as pq

        from fogmon.formats.parquet_log import schema, table
        sch = schema([], {"sample_rate_hz": rec.meta["sample_rate_hz"]})
        pq.write_table(table(sch, rec.t_s[:400], rec.rate_dph[:400], {}), out)
    with open(out, "rb") as fh:
        return fh.read()


def mutate(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    """One mutation (or two) of ``data`` and what it was."""
    out, what = bytearray(data), []
    for _ in range(rng.choice((1, 1, 1, 2))):
        kind = rng.choice(("flip", "flip", "truncate", "insert"))
        if kind == "flip" and out:
            n = rng.randint(1, 16)
            for _ in range(n):
                i = rng.randrange(len(out))
                out[i] ^= 1 << rng.randrange(8)
            what.append(f"flip{n}")
        elif kind == "truncate" and out:
            n = rng.randrange(len(out))
            del out[n:]
            what.append(f"trunc@{n}")
        else:
            i = rng.randrange(len(out) + 1)
            out[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
            what.append(f"insert@{i}")
    return bytes(out), "+".join(what)


def _read(path: str, options: dict) -> None:
    """What the commands do with a file: list it, open it and read every block."""
    from fogmon.sources.open import file_info, open_replay_source
    from fogmon.sources.options import SourceOptions
    opts = SourceOptions(**options)
    file_info(path, opts)
    src = open_replay_source(path, opts)
    for _ in src.blocks():
        pass
    src.close()


def _worker(inbox, outbox, max_gb: float) -> None:
    import resource
    import warnings

    from fogmon.errors import FogmonError, FogmonWarning
    limit = int(max_gb * 2 ** 30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    warnings.simplefilter("ignore", FogmonWarning)       # fogmon's own warnings are meant for the terminal
    capture = tempfile.TemporaryFile()  # noqa: SIM115 (the worker's whole life)
    saved = os.dup(1), os.dup(2)
    while True:
        job = inbox.get()
        if job is None:
            return
        path, options = job
        capture.seek(0)
        capture.truncate()
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(capture.fileno(), 1)
        os.dup2(capture.fileno(), 2)
        try:
            _read(path, options)
            result = ("ok", "")
        except FogmonError as e:
            result = ("memory" if "MemoryError" in str(e) else "error", str(e))
        except BaseException:  # noqa: BLE001 (the fuzzer's job: every other exception is a finding)
            result = ("traceback", traceback.format_exc(limit=-4))
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
        stray = capture.tell()
        outbox.put((*result, stray))


class Runner:
    """A worker process that reads inputs, restarted when it hangs or dies."""

    def __init__(self, timeout_s: float, max_gb: float) -> None:
        self.timeout_s, self.max_gb = timeout_s, max_gb
        self.ctx = mp.get_context("fork")
        self._start()

    def _start(self) -> None:
        self.inbox, self.outbox = self.ctx.Queue(), self.ctx.Queue()
        self.proc = self.ctx.Process(target=_worker, args=(self.inbox, self.outbox, self.max_gb), daemon=True)
        self.proc.start()

    def run(self, path: str, options: dict) -> tuple[str, str, int]:
        self.inbox.put((path, options))
        end = time.monotonic() + self.timeout_s
        while True:
            try:
                return self.outbox.get(timeout=0.5)
            except queue.Empty:
                if not self.proc.is_alive():
                    code = self.proc.exitcode
                    self._start()
                    return ("traceback", f"worker died (exit code {code}: a crash in a library)", 0)
                if time.monotonic() > end:
                    self.proc.kill()
                    self.proc.join()
                    self._start()
                    return ("hang", f"no answer within {self.timeout_s:g} s", 0)

    def close(self) -> None:
        self.inbox.put(None)
        self.proc.join(5)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="mutated inputs per format (default 1000)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout-s", type=float, default=60.0, help="per input (default 60 s)")
    ap.add_argument("--max-gb", type=float, default=4.0, help="the worker's address-space limit (default 4 GiB)")
    ap.add_argument("--only", help="comma list of format names")
    ap.add_argument("--show", type=int, default=3, help="failures shown per format")
    args = ap.parse_args(argv)
    formats = [f for f in FORMATS if not args.only or f.name in args.only.split(",")]
    runner = Runner(args.timeout_s, args.max_gb)
    total = {"traceback": 0, "hang": 0}
    t_start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="fogmon-fuzz-") as folder:
        for fmt in formats:
            if fmt.base is None:
                base = _made(fmt, folder)
            else:
                with open(os.path.join(PUBLIC, fmt.base), "rb") as fh:
                    base = fh.read()
            rng = random.Random(f"{args.seed}:{fmt.name}")
            counts = {"ok": 0, "error": 0, "memory": 0, "traceback": 0, "hang": 0}
            stray, shown, slowest = 0, 0, 0.0
            for i in range(args.n):
                data, what = mutate(base, rng)
                path = os.path.join(folder, f"in{fmt.suffix}")
                with open(path, "wb") as fh:
                    fh.write(data)
                t0 = time.monotonic()
                kind, text, n_stray = runner.run(path, fmt.options)
                slowest = max(slowest, time.monotonic() - t0)
                counts[kind] += 1
                stray += n_stray > 0
                if kind in total and shown < args.show:
                    shown += 1
                    print(f"  {fmt.name} #{i} ({what}): {kind}: {text.strip().splitlines()[-1] if text else ''}")
            for k in total:
                total[k] += counts[k]
            print(f"{fmt.name:11s} {args.n} inputs: {counts['ok']} read, {counts['error']} one-line errors, "
                  f"({counts['memory']} a library's MemoryError), {counts['traceback']} tracebacks, "
                  f"{counts['hang']} hangs, "
                  f"{stray} with stray output; slowest {slowest:.2f} s", flush=True)
    runner.close()
    ok = not any(total.values())
    print(f"{'PASS' if ok else 'FAIL'}: {len(formats)} formats x {args.n} inputs in {time.monotonic() - t_start:.0f} s:"
          f" {total['traceback']} tracebacks, {total['hang']} hangs")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
