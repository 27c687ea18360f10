"""``fogmon inorbit``: the in-orbit evaluation of the in-orbit paper on a recording:
angle random walk from Pauta-cleaned first differences, bias instability as the std of
per-orbit means, and where the energy sits (Daubechies-4 wavelet bands). A multi-axis
recording is evaluated axis by axis (``--axis`` picks some), each line prefixed by its
axis."""
from __future__ import annotations

import argparse

import numpy as np

from fogmon.cli import render
from fogmon.cli.helptext import set_epilog
from fogmon.cli.source_options import add_reader_arguments, source_options
from fogmon.cli.values import number, positive
from fogmon.errors import FogmonError
from fogmon.formats.recording import Recording

EXAMPLES = """
fogmon inorbit replay_logs/sim_in_orbit_1hz.csv
fogmon inorbit orbit3.csv --axis y --period-s 5580 --pauta-k 3.5
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    from fogmon.methods.inorbit import ORBIT_PERIOD_S, PAUTA_K_MIN
    set_epilog(p, EXAMPLES)
    p.add_argument("recording", metavar="RECORDING.csv",
                   help="replay log (rate_dph, or rate_<axis>_dph per axis: each axis evaluated; rot_dps is "
                   "subtracted when present), or another format (docs/formats.md)")
    p.add_argument("--period-s", type=positive, default=ORBIT_PERIOD_S, metavar="SECONDS",
                   help="orbit (cycle) period for the per-cycle bias instability, s, at least 2 samples "
                        f"(default {ORBIT_PERIOD_S:g})")
    p.add_argument("--pauta-k", type=number(PAUTA_K_MIN, above=True), default=3.0, metavar="SIGMAS",
                   help=f"Pauta criterion threshold in sigmas, > sqrt(3) = {PAUTA_K_MIN:.4g} (below it the "
                        "iterated criterion rejects every sample) (default 3)")
    add_reader_arguments(p, axis=True)


def run(args) -> int:
    from fogmon.formats.recording import pick_axes
    from fogmon.methods.inorbit import ARW_MIN_SAMPLES
    from fogmon.sources.open import read_recording

    rec = read_recording(args.recording, source_options(args))
    if len(rec) < ARW_MIN_SAMPLES:
        raise FogmonError(f"{args.recording}: {len(rec)} samples are too few for the in-orbit evaluation (the angle "
                          f"random walk from first differences needs >= {ARW_MIN_SAMPLES})")
    if args.period_s * rec.sample_rate_hz < 2:
        raise FogmonError(f"--period-s {args.period_s:g} s is shorter than 2 samples at {rec.sample_rate_hz:g} Hz")
    axes = pick_axes(rec.axes, args.axis, rec.name) or rec.axis_names()
    for axis in axes:
        rec.for_axis(axis).check_changes()    # a stuck axis: before any output
    for axis in axes:
        for line in evaluate(rec.for_axis(axis), args.period_s, args.pauta_k):
            print(f"{axis}: {line}" if axis else line)
    return 0


def evaluate(rec: Recording, period_s: float, pauta_k: float) -> list[str]:
    """The in-orbit evaluation of a one-axis recording, as the lines printed."""
    from fogmon.methods.inorbit import arw_from_differences, cycle_bias_instability, wavelet_energy

    blk = rec.to_block()
    rate = blk.error_rate_dph
    sample_rate_hz = rec.sample_rate_hz
    arw = arw_from_differences(rate, sample_rate_hz, pauta_k)  # differences across gaps are NaN, dropped
    out = [f"in-orbit evaluation of {rec.name} ({len(rec)} samples at {sample_rate_hz:g} Hz, {rec.duration_s:.0f} s)",
           f"  angle random walk N = {arw.N_dpsh:.4g} deg/sqrt(h) (white rate {arw.sigma_dph:.4g} deg/h per sample; "
           f"{arw.outliers} differences rejected by the {pauta_k:g}-sigma Pauta criterion)"]
    ok = np.isfinite(rate)
    try:
        bi, ncyc = cycle_bias_instability(blk.t_s[ok], rate[ok], period_s)
        out.append(f"  bias instability (std of {ncyc} per-cycle means, {period_s:g} s) = {bi:.4g} deg/h")
    except FogmonError as e:
        out.append(f"  bias instability: not available ({render(e, 'inorbit')})")
    if ok.all():
        out.append("  wavelet (db4) energy by band:")
        out += [f"    {lo:10.4g} .. {hi:<10.4g} Hz  {100 * share:6.2f} %"
                for lo, hi, share in wavelet_energy(rate, sample_rate_hz)]
    else:
        out.append(f"  wavelet energy: skipped, the record has {int((~ok).sum())} missing samples (no interpolation)")
    return out
