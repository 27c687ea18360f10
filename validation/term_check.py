"""How often the whole-record fit's check against the measured ADEV (fogmon.davar.termcheck)
contradicts a term of an exact IEEE-952 record, and what it says on the filtered, the
quantized and the real cases of issue 28 (items 7 and 8).

- ``null``: records of calibration.py's MODELS (all five terms in the mix, 1 Hz to 1 kHz,
  K and R near their limits), each through ``whole_record_fit`` (what ``fogmon replay``
  prints): per model how often a term is contradicted (B, K, R then printed not
  identifiable; Q called white angle noise). The terms add in variance, so on exact
  records a contradiction is a false alarm: PASS when each model's rate is <= 5 % (the
  check's family-wise level over the taus) within 2 binomial sd.
- ``cases``: a white-angle-noise record (Q 1 arcsec, N 0.01 deg/sqrt(h), 100 Hz, 2000 s)
  as simulated (a quantizer on the output) and through a 2-pole 5 Hz Butterworth (the
  model's ``bandwidth`` effect): Q must be called quantization on the first and white
  angle noise on the second; and a flicker floor B 5 deg/h (N 0.01, 100 Hz, 3000 s)
  through a 1 Hz 4-pole Butterworth, whose ADEV at the shortest taus lies far below the
  floor: B must stay identified.

    python validation/term_check.py [--records 40] [--seed 1] [--jobs 2] [--only null|cases]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from multiprocessing import Pool

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from calibration import MODELS, _record, record_seed  # noqa: E402  (the calibration's own records)

from fogmon.davar.record import whole_record_fit  # noqa: E402
from fogmon.sim.model import Effect, Noise, SensorModel  # noqa: E402
from fogmon.sim.simulate import simulate  # noqa: E402

NAMES = ("Q_arcsec", "B_dph", "K_dphsh", "R_dphh")
RATE_LIMIT = 0.05
SD = 2.0


def _null_record(job: tuple[int, int, int]) -> tuple[int, set[str]]:
    k, i, seed = job
    case = MODELS[k]
    rec = _record(case, record_seed(seed, i))
    _, fit = whole_record_fit(rec.rate_dph, None, case.sample_rate_hz)
    return k, {c.name for c in fit.contradicted}


def null_sweep(records: int, seed: int, jobs: int) -> bool:
    todo = [(k, i, seed) for k in range(len(MODELS)) for i in range(records)]
    t0 = time.monotonic()
    if jobs <= 1:
        rows = [_null_record(j) for j in todo]
    else:
        with Pool(jobs) as pool:
            rows = pool.map(_null_record, todo, chunksize=1)
    print(f"null: {records} exact records per model ({time.monotonic() - t0:.0f} s); terms the check "
          f"contradicts (false alarms), per model:")
    print(f"  {'model':<18} " + " ".join(f"{n:>9}" for n in NAMES) + f" {'any':>7}  verdict")
    ok_all = True
    for k, case in enumerate(MODELS):
        hits = [names for kk, names in rows if kk == k]
        rate = {n: np.mean([n in h for h in hits]) for n in NAMES}
        anyr = float(np.mean([bool(h) for h in hits]))
        sd = np.sqrt(RATE_LIMIT * (1 - RATE_LIMIT) / len(hits))
        ok = anyr <= RATE_LIMIT + SD * sd
        ok_all &= ok
        print(f"  {case.name:<18} " + " ".join(f"{100 * rate[n]:8.1f}%" for n in NAMES)
              + f" {100 * anyr:6.1f}%  {'PASS' if ok else 'FAIL'}")
    print(f"null: {'PASS' if ok_all else 'FAIL'} (each model's rate <= {100 * RATE_LIMIT:g} % within {SD:g} "
          f"binomial sd)")
    return ok_all


def cases(seed: int) -> bool:
    noise = Noise(Q_arcsec=1.0, N_dpsh=0.01)
    ok_all = True
    for name, effects, want in (("quantized", [], False),
                                ("filtered", [Effect("bandwidth", {"cutoff_hz": 5.0, "order": 2})], True)):
        rec = simulate(SensorModel(100.0, noise=noise, effects=effects), duration_s=2000.0, seed=seed)
        _, fit = whole_record_fit(rec.rate_dph, None, 100.0)
        q = fit.Q_arcsec
        label = "white angle noise" if fit.q_band_limited else "quantization"
        ok = bool(q.identifiable) and fit.q_band_limited == want
        ok_all &= ok
        print(f"cases: {name:<9} Q {float(q.value):.4g} arcsec [{float(q.lo):.4g}, {float(q.hi):.4g}] called "
              f"{label}: {'PASS' if ok else 'FAIL'}")
    # a flicker floor under a strong filter: the ADEV at the shortest taus falls far below
    # the floor (the filter's doing), yet the floor holds where the record decides it
    m = SensorModel(100.0, noise=Noise(N_dpsh=0.01, B_dph=5.0),
                    effects=[Effect("bandwidth", {"cutoff_hz": 1.0, "order": 4})])
    rec = simulate(m, duration_s=3000.0, seed=seed)
    adev, fit = whole_record_fit(rec.rate_dph, None, 100.0)
    b = fit.B_dph
    ok = bool(b.identifiable) and not fit.contradicted
    ok_all &= ok
    print(f"cases: filtered B 5 deg/h (1 Hz 4-pole, ADEV {adev.adev_dph[0]:.3g} deg/h at {adev.tau_s[0]:g} s): "
          f"B {float(b.value):.4g} [{float(b.lo):.4g}, {float(b.hi):.4g}] deg/h, "
          f"{'identified' if b.identifiable else 'not identified'}: {'PASS' if ok else 'FAIL'}")
    return ok_all


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--records", type=int, default=40, help="records per model of the null sweep (default 40)")
    p.add_argument("--seed", type=int, default=1, help="seed of the records (default 1)")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--only", choices=("null", "cases"), action="append", help="run only this item (repeatable)")
    a = p.parse_args(argv)
    items = set(a.only or ("null", "cases"))
    ok = True
    if "cases" in items:
        ok &= cases(a.seed)
    if "null" in items:
        ok &= null_sweep(a.records, a.seed, a.jobs)
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
