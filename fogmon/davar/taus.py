"""Averaging-time grids: averaging factors m (tau = m / sample_rate_hz, tau in s)."""
from __future__ import annotations

import warnings

import numpy as np

from fogmon.errors import FogmonError, FogmonWarning

# Stable32's "decade" grid: 1, 2, 4 per decade.
_DECADE_STEPS = (1, 2, 4)
#: Most taus per decade an integer ``taus`` may ask for: neighbours are then 7 % apart,
#: denser grids add no independent information (use "all" for every m). Above it an
#: integer is far more likely meant as one tau in s (``taus`` 1000) and is refused.
MAX_PER_DECADE = 32


ANCHORS_PER_OCTAVE = 8
"""Per-tau statistics that cost milliseconds per tau (an EDF's mixture matrices, the exact
interval shape) are computed exactly at up to this many factors per octave and
interpolated in log m between them on denser grids (``anchors``)."""


def anchors(m) -> np.ndarray:
    """Indices into the factors ``m`` (> 0) at which a dense grid's per-tau statistic is
    computed exactly, ordered by m: the first factor of each 1 / ANCHORS_PER_OCTAVE of an
    octave and the largest. On a grid no denser than that every factor is its own anchor."""
    m = np.asarray(m)
    lg = np.log2(m)
    at = np.union1d(np.unique(np.round(lg * ANCHORS_PER_OCTAVE), return_index=True)[1], np.argmax(m))
    return at[np.argsort(m[at], kind="stable")]


def check_per_decade(k: int) -> int:
    """``k`` taus per decade if 1 <= k <= MAX_PER_DECADE, else a FogmonError telling how
    to ask for one tau of k s instead."""
    if not 1 <= k <= MAX_PER_DECADE:
        raise FogmonError(f"taus {k}: an integer is a number of taus per decade, 1..{MAX_PER_DECADE}; "
                          f"for one tau of {k} s give it as {k}.0 (tau values in s have a decimal point "
                          f"or are comma-separated)")
    return k


def _list_s(tau_s) -> str:
    return ("tau " if len(tau_s) == 1 else "taus ") + ", ".join(f"{t:g}" for t in tau_s) + " s"


def tau_grid(sample_rate_hz: float, n_max: int, taus="octave") -> np.ndarray:
    """Averaging factors m (int64, sorted, unique) for ``n_max`` samples at ``sample_rate_hz`` Hz.

    ``taus`` is ``"octave"`` (m = 1, 2, 4, ...), ``"decade"`` (1, 2, 4, 10, 20, 40, ...),
    ``"all"`` (every m), an int k (k log-spaced m per decade, 1 <= k <= MAX_PER_DECADE),
    or an array of tau in s (rounded to the nearest m). Every grid is limited to
    1 <= m <= n_max // 4, beyond which the Allan deviation has too few degrees of freedom
    to mean anything: requested tau values outside it (shorter than half a sample, longer
    than n_max / 4 samples) are left out with a FogmonWarning naming them, and a
    FogmonError if none is left.
    """
    if not sample_rate_hz > 0:
        raise FogmonError(f"sample rate must be > 0 Hz, got {sample_rate_hz}")
    m_max = int(n_max) // 4
    if m_max < 1:
        raise FogmonError(f"need at least 4 samples for an Allan deviation, got {n_max}")
    if isinstance(taus, str):
        if taus == "octave":
            m = 2 ** np.arange(int(np.log2(m_max)) + 1)
        elif taus == "decade":
            m = np.array([s * 10**d for d in range(int(np.log10(m_max)) + 1) for s in _DECADE_STEPS])
        elif taus == "all":
            m = np.arange(1, m_max + 1)
        else:
            raise FogmonError(f"taus must be 'octave', 'decade', 'all', an int per decade or tau values in s, "
                              f"got {taus!r}")
    elif isinstance(taus, (int, np.integer)) and not isinstance(taus, bool):
        k = check_per_decade(int(taus))
        m = np.round(10.0 ** (np.arange(int(np.floor(np.log10(m_max) * k)) + 1) / k))
    else:
        tau_s = np.atleast_1d(np.asarray(taus, dtype=np.float64))
        if tau_s.size == 0 or not np.all(np.isfinite(tau_s)) or np.any(tau_s <= 0):
            raise FogmonError("tau values must be finite and > 0 s")
        m = np.round(tau_s * sample_rate_hz)
        short, long_ = tau_s[m < 1], tau_s[m > m_max]
        limits = (
            f"an Allan deviation needs tau from one sample to n/4 samples, {1 / sample_rate_hz:g} .. "
            f"{m_max / sample_rate_hz:g} s (n = {int(n_max)} samples at {sample_rate_hz:g} Hz, "
            "tau rounded to whole samples)"
        )
        if short.size + long_.size == tau_s.size:
            what = "cannot" if tau_s.size == 1 else "none can"
            raise FogmonError(f"requested {_list_s(tau_s)}: {what} be computed: {limits}")
        if short.size or long_.size:
            warnings.warn(f"{_list_s(np.concatenate([short, long_]))} left out: {limits}", FogmonWarning,
                          stacklevel=1)
    m = np.unique(np.asarray(m, dtype=np.int64))
    return m[(m >= 1) & (m <= m_max)]
