"""``fogmon sim``: simulate a sensor model (TOML, docs/formats.md) into a replay log
(docs/formats.md), optionally --like a recording or driven by a --scenario. A
multi-axis run (docs/sim.md) writes one rate_<axis>_dph column per axis; --axis NAME
writes that axis alone as a one-axis log."""
from __future__ import annotations

import argparse
import itertools
import os
import sys
from typing import TYPE_CHECKING

import numpy as np

from fogmon.cli.helptext import set_epilog
from fogmon.cli.source_options import add_reader_arguments, source_options
from fogmon.cli.values import number, positive
from fogmon.errors import FogmonError

if TYPE_CHECKING:
    from fogmon.formats.recording import Recording
    from fogmon.sim.model import SensorModel


EXAMPLES = """
fogmon sim --model fogmon/data/example_model.toml --duration-s 3600 --out sim.csv --seed 1
fogmon sim --model fogmon/data/example_mwd_model.toml --like replay_logs/sim_mwd_run_1hz.csv --out mwd.csv
fogmon sim --model fogmon/data/example_chamber_model.toml --scenario chamber --out chamber.csv --seed 1
fogmon sim --model replay_logs/sim_in_orbit.toml --scenario orbit --set axes=xyz --duration-s 22320 --out orbit3.csv
"""
NOTES = """The sample rate is the model's ([sensor] sample_rate_hz), or the --like recording's. Rates in
deg/h, times in s, IEEE-952 coefficients in their units (docs/sim.md)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    set_epilog(p, EXAMPLES, NOTES)
    p.add_argument("--model", required=True, metavar="MODEL.toml",
                   help="sensor model file (docs/formats.md): rates deg/h, IEEE-952 noise Q_arcsec, "
                   "N_dpsh deg/sqrt(h), B_dph deg/h, K_dphsh deg/h/sqrt(h), R_dphh deg/h^2, [[effect]] tables")
    p.add_argument("--out", required=True, metavar="SIM.csv", help="replay log to write (docs/formats.md): "
                   "SIM.csv, or SIM.parquet for a Parquet replay log")
    p.add_argument("--like", metavar="RECORDING.csv", help="take the time base (sample times, gaps, sample rate) "
                   "and every aux column (temp_c, rot_dps, vib_g, ...) from this replay log, exactly")
    p.add_argument("--duration-s", type=positive, metavar="SECONDS",
                   help="length in s (required without --like/--scenario; with --like: only the first SECONDS of "
                   "the recording; with --scenario mwd/orbit: its length)")
    p.add_argument("--seed", type=number(0, integer=True), metavar="SEED", help="random seed, an integer >= 0 "
                   "(default: fresh entropy, written to the "
                   "output's metadata so the run can be repeated)")
    p.add_argument("--scenario", choices=("mwd", "chamber", "orbit"), metavar="mwd|chamber|orbit",
                   help="generate the aux channels when there is no recording: mwd = drilling run (stands, "
                   "connections with pumps off, geothermal heating, vibration, string rotation), chamber = "
                   "thermal-chamber plateaus joined by 1 C/min ramps, "
                   "orbit = 5580 s orbit heating and orbital rate; --set axes=xyz for a three-axis gyro; "
                   "see docs/sim.md for every parameter")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario parameter (repeatable), e.g. --set rop_mph=10 --set stick_slip=true; "
                   "lists as --set plateaus_c=20,-40,60")
    add_reader_arguments(p, axis=True)   # for --like in another format (docs/readers.md)


def _overrides(items: list[str]) -> dict[str, str]:
    out = {}
    for it in items:
        if "=" not in it:
            raise FogmonError(f"--set {it!r}: expected KEY=VALUE")
        k, v = it.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def _first_seconds(rec, duration_s: float):
    from fogmon.formats.recording import Recording
    keep = rec.t_s < rec.t_s[0] + duration_s - 0.5 / rec.sample_rate_hz
    if not keep.any():
        raise FogmonError(f"--duration-s {duration_s:g} is shorter than one sample of {rec.name}")
    return Recording(rec.t_s[keep], rec.rate_dph[keep], {k: v[keep] for k, v in rec.aux.items()},
                     dict(rec.meta), rec.path, axes=rec.axes, line_of=rec.line_of)  # a prefix: the same lines


def run(args) -> int:
    from fogmon.cli.output_options import check_command_outputs
    from fogmon.formats.log_writer import check_log_suffix
    from fogmon.sim.model import load_model
    from fogmon.sim.simulate import iter_simulate, simulated_axes

    check_command_outputs(args)
    check_log_suffix("`out`", args.out)
    model = load_model(args.model)
    if args.set and not args.scenario:
        raise FogmonError("--set needs --scenario")
    if args.like and args.scenario:
        raise FogmonError("give --like or --scenario, not both")
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy)  # type: ignore[arg-type]
    meta = {"sensor": f"fogmon sim of {os.path.basename(args.model)}", "model": args.model, "seed": str(seed)}
    like = aux = aux_t = None
    axes: tuple[str, ...] = ()
    duration = args.duration_s
    if args.like:
        like, duration, n_expected = _like(args, model, meta)
    elif args.scenario:
        aux, aux_t, axes, n_expected = _scenario(args, model, seed, meta)
    elif duration is None:
        raise FogmonError("give --duration-s, --like RECORDING or --scenario")
    else:
        n_expected = duration * model.sample_rate_hz
    sim_axes = simulated_axes(model, like, axes)
    if args.axis and sim_axes:
        _check_axis(args.axis, sim_axes)
        meta["axis"] = args.axis
    info: dict = {}
    blocks = iter_simulate(model, duration, like, aux, seed, aux_t, meta_out=info, axes=axes,
                           where=f"`model` {args.model}")
    if args.axis:
        blocks = (b.axis(args.axis) for b in blocks)
    n = _write(args.out, blocks, meta, info, n_expected, args.model)
    written = f"axis {args.axis}" if args.axis and sim_axes else "axes " + ", ".join(sim_axes) if sim_axes else ""
    print(f"fogmon sim: wrote {n} samples{' of ' + written if written else ''} at {info['sample_rate_hz']} Hz to "
          f"{args.out} (seed {seed})")
    return 0


def _like(args: argparse.Namespace, model: SensorModel, meta: dict) -> tuple[Recording, float | None, float]:
    """The --like recording (its first --duration-s s if given), the duration left to
    iter_simulate (None: the recording's) and the samples expected; notes ``meta``."""
    from fogmon.sources.open import read_recording

    like = read_recording(args.like, source_options(args))
    duration = args.duration_s
    if duration is not None:
        like = _first_seconds(like, duration)
        duration = None
    meta["like"] = args.like
    if abs(like.sample_rate_hz - model.sample_rate_hz) > 1e-9 * model.sample_rate_hz:
        print(f"fogmon sim: note: simulating at the recording's {like.sample_rate_hz:g} Hz, not the model's "
              f"{model.sample_rate_hz:g} Hz (the noise coefficients hold at any rate)", file=sys.stderr)
    return like, duration, len(like)


def _scenario(args: argparse.Namespace, model: SensorModel, seed: int,
              meta: dict) -> tuple[dict, np.ndarray, tuple[str, ...], float]:
    """The --scenario's aux channels, their times (s), its axes and the samples expected;
    notes ``meta``."""
    from fogmon.sim.scenarios import make_scenario

    try:
        sc = make_scenario(args.scenario, _overrides(args.set), args.duration_s, seed)
    except MemoryError:
        raise FogmonError(f"--scenario {args.scenario}: not enough memory for its aux channels: lower "
                          f"sample_rate_hz or the duration") from None
    meta.update(sc.meta)
    if args.set:
        meta["scenario_set"] = " ".join(args.set)
    return sc.aux, sc.t_s, sc.axes, (sc.t_s[-1] - sc.t_s[0]) * model.sample_rate_hz


def _check_axis(axis: str, axes: tuple[str, ...]) -> None:
    """``--axis`` must name an axis of a multi-axis run (every axis is simulated, the
    one named is written as a one-axis log: its numbers are its column of the whole run)."""
    if axis not in axes:
        raise FogmonError(f"--axis {axis}: the simulation has no such axis (its axes: {', '.join(axes)})")


def _write(out: str, blocks, meta: dict, info: dict, n_expected: float, model_path: str) -> int:
    """Write the simulated ``blocks`` as a replay log ``out`` (valid samples; ``info``
    from iter_simulate gives the sample rate): after the first block, the free space is
    checked against ``n_expected`` rows at the bytes per row measured on it; a
    non-finite rate is refused; no file on any error (fogmon.formats.log_writer).
    Returns the samples written."""
    from fogmon.formats.log_writer import LogWriter
    from fogmon.outputs import check_space
    from fogmon.sim.simulate import present_samples

    with np.errstate(over="ignore", invalid="ignore"):   # inf is refused below, by name, not warned about
        first = next(blocks)
        meta = {"sample_rate_hz": info["sample_rate_hz"], **meta}
        with LogWriter(out, list(first.aux), meta, first.axes, name="`out`") as w:   # no half-written replay log
            for i, b in enumerate(itertools.chain([first], blocks)):
                v = present_samples(b)
                _check_finite(b.t_s[v], b.rate_dph[v], model_path)
                w.write(b.t_s[v], b.rate_dph[v], {k: a[v] for k, a in b.aux.items()})
                if i == 0 and w.rows:
                    left = n_expected - w.rows
                    check_space("`out`", out, left * w.bytes_per_row,
                                f"{left:.3g} more rows of {w.bytes_per_row:.1f} bytes (measured on the first {w.rows})")
    return w.rows


def _check_finite(t_s: np.ndarray, rate_dph: np.ndarray, model_path: str) -> None:
    """FogmonError naming the model when a simulated rate is not finite (a coefficient
    too large for float64)."""
    bad = ~np.isfinite(rate_dph.reshape(len(rate_dph), -1)).all(axis=1)
    if bad.any():
        raise FogmonError(f"`model` {model_path}: the simulated rate is not finite at {t_s[bad][0]:g} s (a noise "
                          f"coefficient or an effect of the model too large for float64); nothing written")
