"""Can a fitted IEEE-952 term be as large as the fit says? The measured ADEV decides.

The five terms add in Allan variance, each >= 0, and so does anything else a record holds
(humps, steps, outliers): no term's own Allan deviation, sqrt(A_n tau^n), can exceed the
record's true ADEV at any tau. Where a fitted term's own ADEV lies above the measured
ADEV's one-sided upper bound (at 1 - CHECK_LEVEL / n for the n taus with an interval:
Bonferroni, family-wise CHECK_LEVEL), the measurement contradicts the estimate.

A term is judged only at the taus where it is the fitted model's largest part (where the
record decides it; a refuted B, K or R no longer counts there); B, K and R moreover only
from the measured ADEV's first peak on when it rises from the shortest tau. A low-pass
lowers a record's ADEV below any term's line at taus under the filter's time constant,
where it rises with tau as no IEEE-952 term does: a true flicker floor of 3.24 deg/h
under a 1 Hz 4-pole filter at 100 Hz met an ADEV of 0.098 deg/h at 0.01 s and 0.391
deg/h at 0.04 s, where the fit's model is B alone (the filtered white noise left no N).

- B, K, R (the long-tau terms): the estimate is not identified (a floor fitted on a hump
  whose far side falls below it is no flicker floor); the ADEV bounds the term instead:
  the least over the taus of the coefficient whose own ADEV equals that upper bound
  (``TermContradiction.limit``).
- Q: a quantizer on the output is white in angle up to Nyquist, so its 1/tau slope
  reaches the shortest tau. A Q term above the measured ADEV there is a 1/tau slope
  that does not reach the shortest tau: band-limited white angle noise (a filtered,
  decimated output, the sensor's ``bandwidth``; or the far side of a narrowband signal),
  not quantization. The value keeps its meaning as the level of that 1/tau slope; only
  its name changes.
- N is not judged: a low-pass (the sensor's ``bandwidth``) lowers the shortest taus
  below the white-noise line while N still gives the white level at longer taus.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fogmon.davar.theory import NAMES, POWERS, avar_terms_to_coefficients

#: Family-wise level of the check over the taus of one curve (one-sided upper bounds).
CHECK_LEVEL = 0.05
#: Terms the check judges (N is not: a low-pass lowers the shortest taus below its line).
CHECKED = ("Q_arcsec", "B_dph", "K_dphsh", "R_dphh")


#: Terms of the long taus, judged only from the measured ADEV's first peak on when it rises
#: from the shortest tau (``_first_peak_tau``).
LONG_TAU = ("B_dph", "K_dphsh", "R_dphh")


def first_peak(adev: np.ndarray) -> int:
    """Index of the measured ADEV's first local maximum when it rises from the shortest
    tau - a low-pass's signature (no IEEE-952 term rises there) - else 0. ``adev`` in
    ascending tau."""
    k = 0
    while k + 1 < len(adev) and adev[k + 1] > adev[k]:
        k += 1
    return k


def _first_peak_tau(tau: np.ndarray, adev: np.ndarray) -> float:
    """The tau (s) of the ADEV's ``first_peak``. ``tau`` ascending."""
    return float(tau[first_peak(adev)])


@dataclass(frozen=True)
class TermContradiction:
    """A fitted term the measured ADEV contradicts: ``name`` (with unit), the fit's
    ``value`` (that unit); at ``tau_s`` (s, where its excess is largest) its own ADEV
    ``term_adev_dph`` above the measured ``adev_dph`` and that one's one-sided upper bound
    ``bound_dph`` (deg/h) at ``bound_confidence``; ``limit`` (the name's unit): the
    largest value of the term whose own ADEV stays under the bound at every tau, an
    upper limit at ``limit_confidence`` (1 - the check's family-wise level: the term is
    above it only if some tau's bound fails); ``shortest_tau_s``: the curve's shortest
    tau with an interval."""

    name: str
    value: float
    tau_s: float
    term_adev_dph: float
    adev_dph: float
    bound_dph: float
    bound_confidence: float
    limit: float
    shortest_tau_s: float
    limit_confidence: float = 1.0 - CHECK_LEVEL


def contradictions(tau_s, adev_dph, edf, avar_terms, judged=CHECKED,
                   level: float = CHECK_LEVEL) -> list[TermContradiction]:
    """The terms of ``judged`` (names) with A_n > 0 in ``avar_terms`` ((deg/h)^2 s^-n,
    n = -2..2) whose own ADEV exceeds the measured ADEV's one-sided upper bound at some
    tau where the term is the model's largest part (module docstring); taus without an
    interval (EDF below MIN_EDF) are not used."""
    from fogmon.davar.confidence import chi2_factors

    tau = np.asarray(tau_s, dtype=np.float64)
    adev = np.asarray(adev_dph, dtype=np.float64)
    edf = np.asarray(edf, dtype=np.float64)
    a = np.asarray(avar_terms, dtype=np.float64)
    ok = np.isfinite(adev) & (adev > 0) & np.isfinite(edf)
    if not ok.any() or not np.all(np.isfinite(a)):
        return []
    conf = 1.0 - 2.0 * level / int(ok.sum())   # two-sided at conf: one-sided upper at 1 - level / n
    _, f_hi = chi2_factors(edf[ok], conf)
    use = np.isfinite(f_hi)
    if not use.any():
        return []
    tau, adev, bound = tau[ok][use], adev[ok][use], (adev[ok] * f_hi)[use]
    parts = a[None, :] * tau[:, None] ** POWERS[None, :].astype(float)   # each term's Allan variance per tau
    unfiltered = tau >= _first_peak_tau(tau, adev)
    found: dict[int, TermContradiction] = {}
    changed = True
    while changed:   # a refuted B, K or R no longer hides another term where it was the largest part
        changed = False
        live = parts.copy()
        live[:, [i for i in found if NAMES[i] in LONG_TAU]] = 0.0
        for i, name in enumerate(NAMES):
            if name in judged and a[i] > 0 and i not in found:
                c = _judge(i, tau, adev, bound, live, unfiltered, a)
                if c is not None:
                    found[i], changed = c, True
    level_each = 1.0 - level / int(ok.sum())
    return [replace(found[i], bound_confidence=level_each, limit_confidence=1.0 - level) for i in sorted(found)]


def _judge(i: int, tau: np.ndarray, adev: np.ndarray, bound: np.ndarray, parts: np.ndarray, unfiltered: np.ndarray,
           a: np.ndarray) -> TermContradiction | None:
    """Term ``i`` against the ADEV's upper ``bound`` at the taus where it is the largest of
    ``parts`` (and, for a long-tau term, ``unfiltered``); None when it stays under."""
    name, p = NAMES[i], float(POWERS[i])
    where = unfiltered if name in LONG_TAU else np.ones(len(tau), dtype=bool)
    rules = where & (parts[:, i] >= parts.max(axis=1))
    own = np.sqrt(parts[:, i])
    excess = np.where(rules, own / bound, 0.0)
    j = int(np.argmax(excess))
    if not excess[j] > 1.0:
        return None
    unit = np.zeros(5)
    unit[i] = float(np.min((bound ** 2 / tau ** p)[where]))
    return TermContradiction(name, float(avar_terms_to_coefficients(a)[i]), float(tau[j]), float(own[j]),
                             float(adev[j]), float(bound[j]), np.nan, float(avar_terms_to_coefficients(unit)[i]),
                             float(tau.min()))
