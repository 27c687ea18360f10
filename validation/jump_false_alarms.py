"""False alarms of the coefficient-jump events on real stationary records, detection of a
simulated step.

Runs what the pipeline runs on every window (``dadev`` -> ``fit_noise`` ->
``JumpDetector``), hop = window / 8, on:

- the quiet real records (validation/real_recordings.toml: gring_quiet_bjz, px4_quiet_z;
  converted under /work/realdata or --realdata DIR; skipped with a note when absent)
  and the bundled ring-laser replay_logs/lasergyro_z_100hz.csv, each with the pipeline's
  default window (a quarter of the record) and with a short window (1/32 of the record,
  many window pairs): every event there is a false alarm;
- simulated stationary records with heavy tails (Student-t, 5 degrees of freedom: kurtosis
  9, white rate noise plus flicker), 8 h at 20 Hz, window 204.8 s: false alarms;
- the same with N doubled halfway (a 2x white-noise step): the step must be detected
  (an N_dpsh event within two window lengths after it).

Prints per record the events, the window lengths of run compared and the rate per 24 h,
next to the stated rate (``STATED_PER_WINDOW``: union bound over 5 coefficients and the
window / hop = 8 hops of one window pair, 2 Phi(-5) each): PASS when no quiet record
and no stationary simulation exceeds it (with no events observed: none) and every step
is detected.

    python validation/jump_false_alarms.py [--realdata /work/realdata] [--seeds 2] [--skip-real]
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy.signal import fftconvolve
from scipy.stats import norm

from fogmon.davar.batch import dadev
from fogmon.davar.fit import fit_noise
from fogmon.davar.jumps import JUMP_Z, JumpDetector
from fogmon.errors import FogmonWarning
from fogmon.formats.replay_log import read_replay_log
from fogmon.pipeline import default_window_s

ROOT = Path(__file__).resolve().parents[1]
QUIET = ("gring_quiet_bjz_20hz.csv", "px4_quiet_z_250hz.csv")
RLG = ROOT / "replay_logs" / "lasergyro_z_100hz.csv"
HOPS_PER_WINDOW = 8
STATED_PER_WINDOW = 5 * HOPS_PER_WINDOW * 2.0 * float(norm.sf(JUMP_Z))
"""Stated false-alarm rate: events per window length of run (all coefficients)."""
SIM_HZ, SIM_S, SIM_WINDOW_S, SIM_DF = 20.0, 8 * 3600.0, 204.8, 5


def run(rate, sample_rate_hz: float, window_s: float, valid=None) -> tuple[list, float, int]:
    """(events, window lengths of run compared, windows) of the jump detector over ``rate``."""
    d = dadev(rate, sample_rate_hz, window_s, window_s / HOPS_PER_WINDOW, valid=valid)
    if not len(d):
        return [], 0.0, 0
    t_end = (np.asarray(d.end_index, dtype=np.float64) + 1) / sample_rate_hz
    events = JumpDetector(window_s).update(fit_noise(d), t_end)
    compared = max(t_end[-1] - t_end[0] - window_s, 0.0) / window_s
    return events, compared, len(d)


def simulate(seed: int, step: bool) -> np.ndarray:
    """Heavy-tailed stationary rate (deg/h): Student-t(SIM_DF) white noise (N = 0.05
    deg/sqrt(h), doubled from halfway with ``step``) plus flicker (B ~ 0.05 deg/h)."""
    rng = np.random.default_rng(seed)
    n = int(SIM_S * SIM_HZ)
    white = rng.standard_t(SIM_DF, size=n) / np.sqrt(SIM_DF / (SIM_DF - 2)) * 60 * 0.05 * np.sqrt(SIM_HZ)
    if step:
        white[n // 2:] *= 2.0
    k = np.arange(1, 2**14)
    h = np.concatenate([[1.0], np.cumprod((k - 0.5) / k)])
    return white + fftconvolve(rng.normal(size=n) * 0.05, h)[:n]


def _line(name: str, window_s: float, events: list, compared: float, windows: int) -> str:
    rate = len(events) / compared * 86400.0 / window_s if compared else float("nan")
    stated = STATED_PER_WINDOW * 86400.0 / window_s
    return (f"  {name:34s} window {window_s:8.2f} s {windows:5d} windows {compared:7.1f} window lengths  "
            f"events {len(events):3d}  = {rate:7.3g}/24 h (stated <= {stated:.3g}/24 h)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default="/work/realdata", help="folder of the converted real records")
    ap.add_argument("--seeds", type=int, default=2, help="simulated records of each kind")
    ap.add_argument("--skip-real", action="store_true", help="simulations only")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", FogmonWarning)
    ok = True
    print(f"stated false-alarm rate: {STATED_PER_WINDOW:.3g} events per window length of run "
          f"(5 coefficients x {HOPS_PER_WINDOW} hops x 2 Phi(-{JUMP_Z:g})); <= 1 per 24 h for windows >= "
          f"{STATED_PER_WINDOW * 86400:.1f} s")
    print("real stationary records (every event is a false alarm):")
    paths = [] if args.skip_real else [Path(args.realdata) / f for f in QUIET] + [RLG]
    for path in paths:
        if not path.exists():
            print(f"  {path.name}: not found (python validation/real_recordings.py rebuilds it)")
            continue
        rec = read_replay_log(path)
        b = rec.to_block()
        sample_rate_hz = rec.sample_rate_hz
        valid = b.valid & np.isfinite(b.rate_dph)
        for label, w in (("default", default_window_s(sample_rate_hz, len(b.rate_dph))),
                         ("short", 2 ** int(np.log2(len(b.rate_dph) / 32)) / sample_rate_hz)):
            events, compared, windows = run(b.rate_dph, sample_rate_hz, w, valid)
            print(_line(f"{path.name} ({label})", w, events, compared, windows))
            for e in events:
                print(f"      {e.t_s:9.1f} s {e.message}")
            ok &= not events
    print(f"simulated stationary, Student-t({SIM_DF}) white + flicker, {SIM_S / 3600:g} h at {SIM_HZ:g} Hz:")
    for seed in range(args.seeds):
        events, compared, windows = run(simulate(seed, False), SIM_HZ, SIM_WINDOW_S)
        print(_line(f"seed {seed}", SIM_WINDOW_S, events, compared, windows))
        ok &= not events
    print("simulated 2x N step halfway (must be detected within 2 windows after it):")
    for seed in range(args.seeds):
        events, _, _ = run(simulate(100 + seed, True), SIM_HZ, SIM_WINDOW_S)
        t_step = SIM_S / 2
        hit = [e for e in events if e.message.startswith("N_dpsh") and t_step <= e.t_s <= t_step + 2 * SIM_WINDOW_S]
        other = [e for e in events if e not in hit]
        good = bool(hit)
        ok &= good
        print(f"  seed {100 + seed}: {f'detected at {hit[0].t_s:.1f} s' if hit else 'NOT detected'}, "
              f"{len(other)} other event(s) {'PASS' if good else 'FAIL'}")
        for e in hit[:1] + other:
            print(f"      {e.t_s:9.1f} s {e.message}")
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
