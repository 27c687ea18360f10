"""Regenerate the viewer screenshots in docs/img/ from the bundled recordings.

    python scripts/screenshots.py [--out docs/img] [--keep TMPDIR]

Runs, as a user would, `fogmon replay replay_logs/lasergyro_z_100hz.csv --rrd ...` (the
README's default) and `fogmon explain replay_logs/sim_in_orbit_1hz.csv --rrd ...`, and
writes a simulated three-axis gyro's .rrd (``three_axis_rrd``), then the Rerun viewer of
rerun-sdk on each .rrd with `--screenshot-to` in a virtual X display, and writes
docs/img/viewer_replay.png, docs/img/viewer_explain.png and docs/img/viewer_axes.png
(halved to 1600 x 1000 pixels, 256-colour palette, < 300 kB each).

Needs, besides fogmon's own dependencies, a virtual X server and a software Vulkan driver
(not fogmon dependencies; on Debian/Ubuntu, as root):

    apt-get install -y xvfb xauth mesa-vulkan-drivers

Each screenshot takes about a minute on 2 cores (software rendering)."""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: Viewer window in logical points (the PNG has twice as many pixels before halving).
WINDOW = "1600x1000"
#: The virtual screen: the pointer starts at its centre, outside the window (drawn at twice
#: its size in pixels), so no view shows a hover tooltip.
SCREEN = "6800x4200"
MAX_BYTES = 300_000
#: The three-axis gyro of viewer_axes.png: white noise and bias instability differing by
#: axis, an orbital-period term on z only (deg/sqrt(h), deg/h, s).
THREE_AXIS_MODEL = """
[sensor]
sample_rate_hz = 10.0
[noise]
Q_arcsec = 0.0
N_dpsh = 0.02
B_dph = 0.004
K_dphsh = 0.0
R_dphh = 0.0
[noise.x]
[noise.y]
N_dpsh = 0.035
[noise.z]
N_dpsh = 0.015
B_dph = 0.01
[[effect]]
kind = "periodic"
axes = ["z"]
period_s = 5580.0
amplitude_dph = 0.05
phase_rad = 0.0
"""
THREE_AXIS_DURATION_S, THREE_AXIS_WINDOW_S = 3600.0, 409.6


def three_axis_aux(t_s):
    """The aux channels of viewer_axes.png (each in its own view): a warming gyro
    (temp_c, deg C) and its supply voltage (supply_v, V) with a 0.2 V dip at 30 min."""
    import numpy as np

    rng = np.random.default_rng(4)
    temp_c = 25.0 + 8.0 * (1.0 - np.exp(-t_s / 900.0)) + 0.02 * rng.standard_normal(len(t_s))
    supply_v = 15.0 - 0.2 * ((t_s > 1800.0) & (t_s < 1900.0)) + 0.005 * rng.standard_normal(len(t_s))
    return {"temp_c": temp_c, "supply_v": supply_v}


def _run(cmd: list[str], what: str) -> None:
    p = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        tail = p.stderr.strip().splitlines()[-1:] or [f"exit {p.returncode}"]
        sys.exit(f"screenshots: {what} failed: {tail[0]}")


def _screenshot(rrd: str, png: str) -> None:
    """The viewer's window on ``rrd`` with its saved layout, as ``png``."""
    from fogmon.sinks.rerun.server import _rerun_binary

    _run(["xvfb-run", "-a", "-s", f"-screen 0 {SCREEN}x24", _rerun_binary(), "--window-size", WINDOW,
          "--screenshot-to", png, rrd], f"rerun --screenshot-to on {rrd}")
    if not os.path.exists(png):
        sys.exit(f"screenshots: the viewer wrote no {png}")


def three_axis_rrd(path: str) -> None:
    """``path``: THREE_AXIS_MODEL simulated (fogmon.sim, one model per axis, seeds 1-3) with
    ``three_axis_aux`` and sent to the Rerun sink as the pipeline does for several axes
    (3-axis blocks, one StreamingDadev and fit per axis). Until `fogmon replay` takes
    several axes."""
    import numpy as np

    from fogmon.block import Block
    from fogmon.davar.fit import fit_noise
    from fogmon.davar.streaming import StreamingDadev
    from fogmon.sim.model import model_from_dict
    from fogmon.sim.simulate import simulate
    from fogmon.sinks.base import StreamInfo, Summary
    from fogmon.sinks.rerun.sink import RerunSink

    model = model_from_dict(tomllib.loads(THREE_AXIS_MODEL))
    axes, sample_rate_hz = model.axes, model.sample_rate_hz
    recs = [simulate(model.for_axis(a), THREE_AXIS_DURATION_S, seed=k + 1) for k, a in enumerate(axes)]
    t, rate = recs[0].t_s, np.column_stack([r.rate_dph for r in recs])
    aux = three_axis_aux(t)
    engines = {a: StreamingDadev(sample_rate_hz, THREE_AXIS_WINDOW_S, hop_s=THREE_AXIS_WINDOW_S / 8) for a in axes}
    e0 = engines[axes[0]]
    sink = RerunSink(rrd_path=path)
    sink.start(
        StreamInfo(
            "simulated three-axis gyro",
            sample_rate_hz,
            THREE_AXIS_WINDOW_S,
            e0.hop_n / sample_rate_hz,
            e0.m / sample_rate_hz,
            tuple(aux),
            axes=axes,
        )
    )
    for k in range(0, len(t), 36_000):
        block = Block.make(t[k:k + 36_000], rate[k:k + 36_000], aux={n: v[k:k + 36_000] for n, v in aux.items()},
                           axes=axes)
        sink.block(block)
        for a in axes:
            res = engines[a].push(block.axis(a).rate_dph)
            if len(res):
                sink.frames(res, fit_noise(res), t[0] + res.end_index / sample_rate_hz, axis=a)
    sink.finish(Summary("simulated three-axis gyro", sample_rate_hz, THREE_AXIS_WINDOW_S, e0.hop_n / sample_rate_hz))


def _shrink(src: str, dst: str) -> int:
    """Halve ``src`` (means of 2 x 2 pixels: a sharper filter rings at the heatmaps' cell
    edges, drawing dark outlines that look like flagged regions) and store it with an
    adaptive 256-colour palette as ``dst``; its size (bytes)."""
    from PIL import Image

    im = Image.open(src).convert("RGB")
    im = im.resize((im.width // 2, im.height // 2), Image.BOX)
    im.quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(dst, optimize=True)
    return os.path.getsize(dst)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "img"), help="folder of the PNGs (default docs/img)")
    ap.add_argument("--keep", help="keep the .rrd files and full-size PNGs in this folder")
    args = ap.parse_args()
    if shutil.which("xvfb-run") is None:
        sys.exit("screenshots: xvfb-run not found; install a virtual X server and software Vulkan: "
                 "apt-get install -y xvfb xauth mesa-vulkan-drivers")
    work = args.keep or tempfile.mkdtemp(prefix="fogmon-shots-")
    os.makedirs(work, exist_ok=True)
    os.makedirs(args.out, exist_ok=True)
    fogmon = [sys.executable, "-m", "fogmon"]
    replay, explain, axes = (os.path.join(work, f"{n}.rrd") for n in ("replay", "explain", "axes"))
    _run([*fogmon, "replay", "replay_logs/lasergyro_z_100hz.csv", "--rrd", replay, "--no-progress", "--quiet"],
         "fogmon replay")
    _run([*fogmon, "explain", "replay_logs/sim_in_orbit_1hz.csv", "--report", os.path.join(work, "report.json"),
          "--rrd", explain, "--quiet"], "fogmon explain")
    three_axis_rrd(axes)
    try:
        for rrd, name in ((replay, "viewer_replay.png"), (explain, "viewer_explain.png"),
                          (axes, "viewer_axes.png")):
            full = os.path.join(work, name)
            _screenshot(rrd, full)
            size = _shrink(full, os.path.join(args.out, name))
            print(f"wrote {os.path.join(args.out, name)} ({size / 1000:.0f} kB)")
            if size > MAX_BYTES:
                print(f"screenshots: warning: {name} is over {MAX_BYTES / 1000:.0f} kB", file=sys.stderr)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
