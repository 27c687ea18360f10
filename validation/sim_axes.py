"""Validate the simulator's several axes: each axis's noise, their independence and a
common vibration cause, over many seeds.

1. A three-axis model with a different IEEE-952 mixture per axis (x: N; y: Q + N;
   z: N + B + K) simulated ``--seeds`` times (``--samples`` samples at 100 Hz, the
   multi-axis path of ``fogmon.sim.simulate``): per axis sqrt(mean AVAR over seeds) /
   theory (``fogmon.davar.theory.adev_model`` of that axis's [noise.<axis>]) at 8 taus
   per decade over 20 tau0 <= tau <= duration/10. Pass: within 2 % or 3.5 standard
   errors of the seed mean, whichever is larger (as validation/sim_noise.py).
2. One vib_g (a square wave 0.1 / 3 g, 10 s each) driving a vibration_noise effect on
   every axis: the correlation r of the rates of two axes, divided by its standard
   deviation for independent series with this variance profile (sqrt(sum w^2) / sum w,
   w = N(t)^2), must scatter as a standard normal (mean within 4 standard errors of 0,
   standard deviation 0.9..1.1); the correlation of the axes' per-second mean square
   (the common level) must exceed 0.9 in every record.

    python validation/sim_axes.py               # 300 seeds, ~1 min

Exit code 0 when everything passes.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from fogmon.davar.batch import oadev
from fogmon.davar.theory import adev_model
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate

SAMPLE_RATE_HZ = 100.0
NOISE = {"x": Noise(N_dpsh=0.05), "y": Noise(Q_arcsec=0.5, N_dpsh=0.02),
         "z": Noise(N_dpsh=0.02, B_dph=0.1, K_dphsh=30.0)}
PAIRS = ((0, 1), (0, 2), (1, 2))


def axes_adev(seeds: int, n: int) -> bool:
    """Part 1: per-axis ADEV of the three-axis simulation against each axis's theory."""
    model = SensorModel(SAMPLE_RATE_HZ, 0.0, Noise(), axis_noise=dict(NOISE))
    avars: list[list[np.ndarray]] = [[] for _ in NOISE]
    tau = np.zeros(0)
    for s in range(seeds):
        rec = simulate(model, duration_s=n / SAMPLE_RATE_HZ, seed=s)
        for j in range(len(NOISE)):
            res = oadev(rec.rate_dph[:, j], SAMPLE_RATE_HZ, taus=8, alpha=0)
            avars[j].append(res.adev_dph ** 2)
            tau = res.tau_s
    sel = (tau >= 20 / SAMPLE_RATE_HZ - 1e-12) & (tau <= n / SAMPLE_RATE_HZ / 10 + 1e-12)
    ok = True
    for j, (axis, nz) in enumerate(NOISE.items()):
        a = np.array(avars[j])[:, sel]
        ratio = np.sqrt(a.mean(0)) / adev_model(tau[sel], nz.Q_arcsec, nz.N_dpsh, nz.B_dph, nz.K_dphsh)
        se = a.std(0) / np.sqrt(seeds) / a.mean(0) / 2
        good = bool(np.all(np.abs(ratio - 1) <= np.maximum(0.02, 3.5 * se)))
        ok &= good
        worst = int(np.argmax(np.abs(ratio - 1)))
        terms = ", ".join(f"{k} {v:g}" for k, v in vars(nz).items() if v)
        print(f"{'PASS' if good else 'FAIL'}  axis {axis} ({terms}): taus {tau[sel][0]:.3g}..{tau[sel][-1]:.3g} s, "
              f"sqrt(mean AVAR)/theory {ratio.min():.4f}..{ratio.max():.4f} (worst at tau={tau[sel][worst]:.3g} s, "
              f"s.e. {se[worst]:.4f})")
    return ok


def common_vibration(seeds: int, n: int) -> bool:
    """Part 2: independent white sequences, one common vibration level."""
    t = np.arange(n) / SAMPLE_RATE_HZ
    vib = np.where(np.floor(t / 10.0) % 2 == 0, 0.1, 3.0)
    n0, gain = 0.01, 0.05
    model = SensorModel(SAMPLE_RATE_HZ, 0.0, Noise(N_dpsh=n0),
                        [Effect("vibration_noise", {"n_gain_dpsh_per_g": gain})],
                        axis_noise={a: Noise(N_dpsh=n0) for a in NOISE})
    w = (n0 + gain * vib) ** 2
    sd_r = np.sqrt(np.sum(w ** 2)) / np.sum(w)
    z, power_r = [], []
    per_s = int(SAMPLE_RATE_HZ)
    for s in range(seeds):
        r = simulate(model, aux={"vib_g": vib}, seed=s).rate_dph
        power = (r[: n - n % per_s].reshape(-1, per_s, 3) ** 2).mean(axis=1)
        for i, j in PAIRS:
            z.append(np.corrcoef(r[:, i], r[:, j])[0, 1] / sd_r)
            power_r.append(np.corrcoef(power[:, i], power[:, j])[0, 1])
    za = np.array(z)
    ok_z = abs(za.mean()) <= 4 / np.sqrt(len(za)) and 0.9 <= za.std() <= 1.1
    ok_p = min(power_r) > 0.9
    print(f"{'PASS' if ok_z else 'FAIL'}  rate correlation / its sd for independent axes ({sd_r * np.sqrt(n):.3f}"
          f"/sqrt(n)), {len(za)} axis pairs: mean {za.mean():+.3f} (limit +-{4 / np.sqrt(len(za)):.3f}), "
          f"sd {za.std():.3f} (0.9..1.1), largest |z| {np.abs(za).max():.2f}")
    print(f"{'PASS' if ok_p else 'FAIL'}  correlation of the per-second mean square (the common vib_g level): "
          f"min {min(power_r):.4f}, mean {np.mean(power_r):.4f} (limit > 0.9)")
    return ok_z and ok_p


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=300, help="records per part (>= 20)")
    ap.add_argument("--samples", type=int, default=16384, help="samples per record")
    a = ap.parse_args(argv)
    ok = axes_adev(a.seeds, a.samples)
    ok &= common_vibration(a.seeds, a.samples)
    print("ALL PASS" if ok else "SOME FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
