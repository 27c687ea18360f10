"""`fogmon batch INPUTS... --out DIR`: many recordings analysed on Dask with the engine and
fits of `fogmon replay`, into DIR/windows.parquet and DIR/recordings.parquet (docs/batch.md,
the output tables); `--report` adds the fleet report."""
from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import time

from fogmon import stopping
from fogmon.cli.helptext import set_epilog
from fogmon.cli.values import number, positive
from fogmon.errors import FogmonError
from fogmon.pipeline import PipelineConfig
from fogmon.sources.options import SourceOptions

#: default chunk length in samples (4.7 h at 1 kHz): long recordings are split into chunks
DEFAULT_CHUNK_SAMPLES = 1 << 24
#: give up when the cluster has had no worker for this long (s): at the start (a
#: --scheduler nobody serves) and while tasks wait (every worker died)
NO_WORKER_S = 60.0
#: how often (s) waiting tasks check that the cluster still has a worker
POLL_S = 2.0
#: the address schemes of a Dask scheduler on the network (Dask's comm backends but
#: inproc, which only a scheduler in this process has)
SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")

EXAMPLES = """
fogmon batch runs/ --out fleet/                          # every recording under runs/, on this machine
fogmon batch 'rig*/gyro-*.parquet' archives/ --out fleet/ --model datasheet.toml --report fleet/fleet.html
fogmon batch runs/ --out fleet/ --scheduler tcp://10.0.0.5:8786   # an existing Dask cluster
fogmon batch runs/ --out fleet/ --report fleet/fleet.html --group-by serial   # gyros by a header field
"""
NOTES = """Inputs: replay logs (.csv), Parquet logs (.parquet), raw serial captures with their .json
sidecar (or --protocol), CAN logs (.asc .blf .trc .csv .log with --dbc or a sidecar),
monitor archive folders; a folder is searched for them (an archive folder is one
recording), a glob is expanded. Every input is checked (all rows) before any analysis
starts. One task per recording and axis; a recording longer than --chunk-s is split
into chunks overlapping by one window, with results equal to a single pass
(docs/batch.md). Window, hop and taus are chosen per recording as `fogmon replay` does.
Every readable recording is analysed; one that cannot be read is named on stderr and in
recordings.parquet (column error) and left out. When the cluster has no worker for
60 s (none connected, or all died), batch gives up with an error. Rates in deg/h, times
in s, coefficients in IEEE-952 units (Q arcsec, N deg/sqrt(h), B deg/h, K deg/h/sqrt(h),
R deg/h^2)."""
EXIT_CODES = """exit codes:
  0              every recording was analysed
  1              some analyses failed (named on stderr and in recordings.parquet, column error)
  2              bad usage or input: one line names the option, or the file, line and field;
                 also when some inputs could not be read (the others analysed and written),
                 none could (nothing written), or no worker is left
  130, 143, 129  stopped by Ctrl-C, SIGTERM, SIGHUP"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from fogmon.cli.pipeline_options import parse_taus
    from fogmon.cli.source_options import add_reader_arguments, add_source_arguments

    set_epilog(parser, EXAMPLES, NOTES, EXIT_CODES)
    parser.add_argument("inputs", nargs="+", metavar="INPUT", help="recording files, folders or globs")
    parser.add_argument("--out", required=True, metavar="DIR", help="folder for windows.parquet and "
                        "recordings.parquet (created if needed, outside the input folders; existing tables there are "
                        "replaced)")
    parser.add_argument("--scheduler", type=scheduler_address, metavar="ADDRESS",
                        help="a running Dask scheduler (tcp://HOST:PORT; start one with `dask scheduler` and "
                        "workers with `dask worker ADDRESS --nthreads 1`); the workers must see the input paths. "
                        "Default: a local cluster of --workers processes")
    parser.add_argument("--workers", type=number(1, 1024, integer=True), metavar="PROCESSES",
                        help=f"processes of the local cluster, one thread each (default: the machine's cores, "
                             f"{len(os.sched_getaffinity(0))} here)")
    parser.add_argument("--model", metavar="MODEL.toml", help="also explain every recording against this sensor "
                        "model (the explain score before/after and the effect kinds per recording)")
    parser.add_argument("--report", metavar="FLEET.html", help="write the fleet report (HTML with its PNG figures "
                        "and a CSV of the per-recording table beside it)")
    parser.add_argument("--group-by", metavar="KEY",
                        help="what names a recording's gyro in the fleet report: a metadata key (a replay-log "
                        "header '# KEY: value' line, a Parquet log's metadata, a capture sidecar field), 'folder' "
                        "(each folder one gyro) or 'recording' (each its own). Default: a serial number "
                        "(serial_number, serial, sn, ...), else the sensor name within its folder, else the "
                        "recording alone; never the folder alone (docs/batch.md, Gyros)")
    parser.add_argument("--chunk-s", type=positive, metavar="SECONDS", help="split recordings longer than SECONDS of "
                        f"recording time into chunks (default {DEFAULT_CHUNK_SAMPLES:,} samples: "
                        f"{DEFAULT_CHUNK_SAMPLES / 1000 / 3600:.1f} h at 1 kHz)")
    g = parser.add_argument_group("dynamic Allan deviation (as fogmon replay)")
    g.add_argument("--window-s", type=positive, metavar="SECONDS",
                   help="window length in s (default: as fogmon replay, "
                   "per recording: a quarter of it rounded down to a power of two of samples)")
    g.add_argument("--hop-s", type=positive, metavar="SECONDS", help="hop in s (default: window/8)")
    g.add_argument("--taus", default=PipelineConfig.taus, type=parse_taus, metavar="GRID",
                   help=f"averaging times as fogmon replay --taus (default {PipelineConfig.taus})")
    g.add_argument("--raw-rate", action="store_true", help="analyse rate_dph as recorded even with rot_dps")
    g.add_argument("--keep-motion", action="store_true", help="analyse platform motion too (docs/motion.md)")
    parser.add_argument("--no-progress", action="store_true", help="no Dask progress bar")
    add_source_arguments(parser, mode="replay")
    add_reader_arguments(parser)


def scheduler_address(text: str) -> str:
    """argparse ``type=`` of --scheduler: a Dask scheduler address, [SCHEME://]HOST:PORT
    with a scheme of ``SCHEMES`` and a port in 1..65535 (or the inproc:// address of a
    scheduler in this process), checked before any work; a usage error otherwise."""
    from distributed.comm import parse_address, parse_host_port

    rule = "must be a Dask scheduler address tcp://HOST:PORT"
    try:
        scheme, loc = parse_address(text, strict=False)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{rule}, got {text!r}") from None
    if scheme == "inproc":
        return text
    if scheme not in SCHEMES:
        raise argparse.ArgumentTypeError(f"{rule} (scheme one of {', '.join(SCHEMES)}), got {text!r}")
    try:
        host, port = parse_host_port(loc)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{rule} (PORT missing or not a number), got {text!r}") from None
    if not host or not 1 <= int(port) <= 65535:
        raise argparse.ArgumentTypeError(f"{rule} (a host and a port in 1..65535), got {text!r}")
    return text


def _options(args: argparse.Namespace) -> tuple[SourceOptions, PipelineConfig]:
    """What the tasks need (frozen dataclasses, picklable): how to read every recording
    and how to analyse it."""
    from fogmon.cli.source_options import source_options

    return source_options(args), PipelineConfig(window_s=args.window_s, hop_s=args.hop_s, taus=args.taus,
                                                raw_rate=args.raw_rate, keep_motion=args.keep_motion)


def _local_cluster(n: int):
    """A local cluster of ``n`` worker processes, one thread each, that leave Ctrl-C to
    this process (a terminal sends it to the whole process group; this process stops
    them cleanly, so an interrupted batch prints no worker tracebacks): the workers are
    forked from multiprocessing's fork server, started here with SIGINT ignored, which
    every process forked from it inherits (also a worker restarted later). SIGINT is
    ignored only while the fork server process is started (milliseconds)."""
    import multiprocessing.forkserver

    import dask
    from distributed import LocalCluster

    if threading.current_thread() is threading.main_thread():
        handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            multiprocessing.forkserver.ensure_running()
        finally:
            signal.signal(signal.SIGINT, handler)
    cluster = None
    # a Ctrl-C while the cluster starts interrupts once it has started (then it is closed); the
    # workers' own log lines stay off the terminal (a recording's failure is reported by its
    # task; workers stopped with the cluster would log heartbeat errors)
    try:
        with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}), stopping.shielded():
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                                   silence_logs=logging.CRITICAL)
    except KeyboardInterrupt:
        if cluster is not None:
            _quiet_shutdown()
            cluster.close()
        raise
    return cluster


def _client(args):
    from distributed import Client

    if args.scheduler:
        try:
            client = Client(args.scheduler, timeout=30)
        except (OSError, TimeoutError, ValueError) as e:   # ValueError: an address Dask cannot use
            raise FogmonError(f"--scheduler {args.scheduler}: cannot connect: {e}") from None
        try:
            client.wait_for_workers(1, timeout=NO_WORKER_S)
        except TimeoutError:
            client.close()
            raise FogmonError(f"--scheduler {args.scheduler}: no Dask worker in {NO_WORKER_S:g} s (start one with "
                              f"`dask worker {args.scheduler}`)") from None
        return client, None
    cluster = _local_cluster(args.workers or len(os.sched_getaffinity(0)))
    return Client(cluster), cluster


def _quiet_shutdown() -> None:
    """After Ctrl-C: the client's pending waits end with errors nobody collects; asyncio
    and distributed would print them as tracebacks at exit."""
    for name in ("asyncio", "distributed", "tornado"):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def run(args: argparse.Namespace) -> int:
    from fogmon.cli.output_options import check_command_outputs
    from fogmon.fleet.inputs import check_outside_inputs, expand_inputs

    paths = expand_inputs(args.inputs)
    check_outside_inputs([("`out`", args.out, True), ("`report`", args.report, False)], args.inputs)
    check_command_outputs(args, paths)
    _check_model(args)
    source, config = _options(args)
    show = not args.no_progress and sys.stdout.isatty()     # Dask's text progress bar writes to stdout
    client, cluster = _client(args)
    try:
        if show:
            print(f"fogmon batch: {len(paths)} recordings on {len(client.scheduler_info()['workers'])} Dask workers "
                  f"({args.scheduler or 'local cluster'})", file=sys.stderr)
        plans, bad = _check_inputs(client, paths, source, config, show, args.scheduler)
        _make_out(args.out)                      # some input is readable: the outputs can be written
        jobs = _submit(client, plans, args, source, config)
        if show:
            from distributed import progress
            progress([f for j in jobs for f in j[3]] + [j[4] for j in jobs if j[4] is not None])
        windows, rows, accels = _gather(client, jobs, args.scheduler, args.group_by)
    except KeyboardInterrupt:
        _quiet_shutdown()
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return _finish(args, plans, bad, jobs, windows, rows, accels)


def _make_out(folder: str) -> None:
    """The --out folder (in an existing one: checked before); FogmonError on a full disk."""
    from fogmon.outputs import write_failed

    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        raise write_failed("`out`", folder, e) from None


def _check_model(args: argparse.Namespace) -> None:
    """FogmonError unless --model reads as a sensor model (before any work)."""
    if args.model and not os.path.isfile(args.model):
        raise FogmonError(f"--model {args.model}: no such file")
    if args.model:
        from fogmon.sim.model import load_model
        load_model(args.model)


def _wait(client, futures: list, scheduler: str | None) -> None:
    """Wait until ``futures`` are done; FogmonError when the cluster has had no worker
    for NO_WORKER_S s meanwhile (every worker died: nothing can run any more)."""
    from distributed import wait

    alone_since: float | None = None
    while True:
        try:
            wait(futures, timeout=POLL_S)
            return
        except TimeoutError:
            pass
        if client.scheduler_info(n_workers=-1).get("workers"):
            alone_since = None
            continue
        now = time.monotonic()
        alone_since = alone_since if alone_since is not None else now
        if now - alone_since >= NO_WORKER_S:
            left = sum(not f.done() for f in futures)
            raise FogmonError(f"no Dask worker left at {scheduler or 'the local cluster'} for {NO_WORKER_S:g} s "
                              f"({left} of {len(futures)} tasks not done): nothing written")


def _result(future, failed):
    """A task's result, or ``failed(message)`` when the task itself failed on the cluster
    (e.g. KilledWorker: its worker died each time it ran it)."""
    if future.status == "error":
        e = future.exception()
        return failed(f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}".rstrip(": "))
    return future.result()


def _check_inputs(client, paths: list[str], source: SourceOptions, config: PipelineConfig, show: bool,
                  scheduler: str | None) -> tuple[list, list]:
    """Every input checked on the cluster (all rows): the plans of the readable ones and
    those of the unreadable (each named on stderr now); FogmonError when none is readable."""
    from distributed import progress

    from fogmon.cli import render
    from fogmon.fleet import tasks

    checks = client.map(tasks.check, paths, source=source, config=config,
                        key=[f"check-{i}" for i in range(len(paths))])
    if show:
        progress(checks)
    _wait(client, checks, scheduler)
    plans = [_result(f, lambda msg, p=p: tasks.Plan(p, kind=tasks.input_kind(p), error=msg))
             for f, p in zip(checks, paths, strict=True)]
    bad = [p for p in plans if p.error]
    for p in bad:
        print(f"fogmon batch: error: {render(p.error, 'batch')}", file=sys.stderr)
    if len(bad) == len(plans):
        raise FogmonError(f"no input could be read ({len(bad)} named above): nothing analysed")
    return [p for p in plans if not p.error], bad


def _submit(client, plans: list, args: argparse.Namespace, source: SourceOptions,
            config: PipelineConfig) -> list[tuple]:
    """The tasks of every recording and axis, submitted: one tuple per (recording, axis) of
    (plan, axis, chunks, [chunk futures], explain future or None, motion future or None)."""
    from fogmon.fleet import tasks
    from fogmon.fleet.chunks import plan_chunks
    from fogmon.pipeline import OVERALL_MAX_SAMPLES

    jobs: list[tuple] = []
    for i, plan in enumerate(plans):
        w = int(round(plan.window_s * plan.sample_rate_hz))
        h = int(round(plan.hop_s * plan.sample_rate_hz))
        size = int(round(args.chunk_s * plan.sample_rate_hz)) if args.chunk_s else DEFAULT_CHUNK_SAMPLES
        chunks = plan_chunks(plan.n_samples, w, h, max(size, w), OVERALL_MAX_SAMPLES)
        for axis in plan.axes or ("",):   # a recording of several axes: each axis on its own
            key = f"{i}-{axis}" if axis else f"{i}"
            masked = None
            if len(chunks) > 1 and not args.keep_motion:
                masked = client.submit(tasks.motion_pass, plan, source, config, axis, key=f"motion-{key}")
            futs = [client.submit(tasks.run_chunk, plan, c, source, config, masked, axis,
                                  key=f"chunk-{key}-{c.index}") for c in chunks]
            expl = client.submit(tasks.explain_recording, plan.path, args.model, source, config, axis,
                                 key=f"explain-{key}") if args.model else None
            jobs.append((plan, axis, chunks, futs, expl, masked))
    return jobs


def _gather(client, jobs: list[tuple], scheduler: str | None,
            group_by: str | None = None) -> tuple[list, list[dict], tuple[list, list[dict]]]:
    """The results of ``jobs``: the windows tables (pyarrow, one per recording analysed),
    the recordings-table rows (their errors as this command names options; their gyro as
    ``group_by`` asks) and the accelerometers' windows tables and rows."""
    from fogmon.cli import render
    from fogmon.fleet import tasks

    _wait(client, [f for j in jobs for f in (*j[3], j[4], j[5]) if f is not None], scheduler)
    windows: list = []
    rows: list[dict] = []
    accel_windows: list = []
    accel_rows: list[dict] = []
    for plan, axis, chunks, futs, expl, masked in jobs:
        path = plan.path
        results = [_result(f, lambda msg, c=c, path=path: tasks.ChunkResult(path, c.index, error=msg))
                   for f, c in zip(futs, chunks, strict=True)]
        motion = (_result(masked, lambda msg, path=path: tasks.MotionResult(path, error=msg))
                  if masked is not None else None)
        row, win = _recording_row(plan, axis, chunks, results, motion, group_by)
        if expl is not None:
            row.update(_result(expl, lambda msg: {"explain_score_before": float("nan"),
                                                  "explain_score_after": float("nan"), "explain_effects": "",
                                                  "explain_error": msg}))
        for k in ("error", "explain_error"):
            if row.get(k):
                row[k] = render(row[k], "batch")
        rows.append(row)
        if win is not None:
            windows.append(win)
            for accel_row, accel_win in _accel_rows(plan, results):
                accel_rows.append(accel_row)
                accel_windows.append(accel_win)
    return windows, rows, (accel_windows, accel_rows)


def _finish(args: argparse.Namespace, plans: list, bad: list, jobs: list[tuple], windows: list,
            rows: list[dict], accels: tuple[list, list[dict]] = ([], [])) -> int:
    """Write the tables (and --report), say what was done, what failed and what could
    not be read; the exit code."""
    from fogmon.cli import render
    from fogmon.fleet import tables

    failed = [row for row in rows if row["error"]]
    unread = [{"recording": p.path, "axis": "-", "format": p.kind, "error": render(p.error, "batch")} for p in bad]
    w_path, r_path = tables.write_tables(args.out, windows, rows + unread, *accels)
    for row in failed:
        print(f"fogmon batch: {row['recording']}: failed: {row['error']}", file=sys.stderr)
    for row in rows:
        if row.get("explain_error"):
            print(f"fogmon batch: {row['recording']}: explain failed: {row['explain_error']}", file=sys.stderr)
    n_win = sum(len(t) for t in windows)
    what = "(recording, axis) pairs" if any(p.axes for p in plans) else "recordings"
    print(f"fogmon batch: {len(rows) - len(failed)} of {len(rows)} {what} analysed "
          f"({sum(len(j[2]) for j in jobs)} chunks): {n_win} windows in {w_path}, one row per recording in {r_path}")
    if accels[1]:
        print(f"fogmon batch: {len(accels[1])} accelerometers: {sum(len(t) for t in accels[0])} windows in "
              f"{os.path.join(args.out, tables.ACCEL_WINDOWS)}, one row each in "
              f"{os.path.join(args.out, tables.ACCEL_RECORDINGS)}")
    if args.report:
        from fogmon.cli import command_flags
        from fogmon.fleet.report import gyro_summary, write_report
        for f in write_report(args.report, r_path, w_path, command_flags("batch")):
            print(f"fogmon batch: wrote {f}")
        print(f"fogmon batch: the report compares {gyro_summary(rows)}")
    if bad:
        print(f"fogmon batch: error: {len(bad)} of {len(bad) + len(plans)} inputs could not be read (named above "
              f"and in {r_path}); the others are analysed", file=sys.stderr)
        return 2
    return 1 if failed or any(r.get("explain_error") for r in rows) else 0


def _accel_rows(plan, results) -> list[tuple[dict, object]]:
    """The accelerometers' rows and windows tables of one recording's chunks (those of
    an axis's task: that axis's accelerometer)."""
    from fogmon.fleet import tables

    out = []
    last = results[-1]
    for a, rec in last.accel_records.items():
        row = {"recording": plan.path, "accel": a, "sample_rate_hz": plan.sample_rate_hz, "window_s": plan.window_s,
               "hop_s": plan.hop_s, "samples_invalid": sum(r.accel_invalid.get(a, 0) for r in results),
               "windows": sum(len(r.accel_windows.get(a, {}).get("t_end_s", ())) for r in results), **rec}
        out.append((row, tables.windows_table(plan.path, a, plan.window_s, results[0].tau_s,
                                              [r.accel_windows.get(a, {}) for r in results], accel=True)))
    return out


def _recording_row(plan, axis: str, chunks, results, motion, group_by: str | None = None) -> tuple[dict, object]:
    """The recordings-table row of one recording's axis ``axis`` ("": a one-axis
    recording, named by ``plan.axis``; its gyro as ``group_by`` asks, fleet.identity) and
    its windows table (None if failed)."""
    from fogmon.fleet import tables
    from fogmon.fleet.identity import gyro_identity

    gyro, named_by = gyro_identity(plan.path, plan.meta, group_by)
    row = {"recording": plan.path, "gyro": gyro, "gyro_named_by": named_by, "axis": axis or plan.axis,
           "format": plan.kind,
           "sample_rate_hz": plan.sample_rate_hz, "window_s": plan.window_s, "hop_s": plan.hop_s, "chunks": len(chunks)}
    errors = [r.error for r in results if r.error]
    last = results[-1].record
    row.update({"duration_s": float("nan"), "samples": sum(r.own_samples for r in results),
                "samples_invalid": sum(r.own_invalid for r in results), "gaps": last.get("gaps", 0),
                "motion_samples_excluded": (motion.samples_excluded if motion is not None
                                            else last.get("motion_samples_excluded", 0)),
                "windows": sum(len(r.windows.get("t_end_s", ())) for r in results),
                "fit_first_s": last.get("fit_first_s", float("nan"))})
    if last:
        row["duration_s"] = last["t_last_s"] - last["t_first_s"] + 1.0 / plan.sample_rate_hz
    for c in tables.coefficient_columns():
        row[c] = last.get(c, False if c.startswith("identifiable_") else float("nan"))
    row["error"] = errors[0] if errors else ""
    if errors:
        return row, None
    return row, tables.windows_table(plan.path, axis or plan.axis, plan.window_s, results[0].tau_s,
                                     [r.windows for r in results])
