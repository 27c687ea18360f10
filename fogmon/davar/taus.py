"""Averaging-time grids: averaging factors m (tau = m / rate_hz, tau in s)."""
from __future__ import annotations

import numpy as np

from fogmon.errors import FogmonError

# Stable32's "decade" grid: 1, 2, 4 per decade.
_DECADE_STEPS = (1, 2, 4)


def tau_grid(rate_hz: float, n_max: int, taus="octave") -> np.ndarray:
    """Averaging factors m (int64, sorted, unique) for ``n_max`` samples at ``rate_hz`` Hz.

    ``taus`` is ``"octave"`` (m = 1, 2, 4, ...), ``"decade"`` (1, 2, 4, 10, 20, 40, ...),
    ``"all"`` (every m), an int k (k log-spaced m per decade), or an array of tau in s
    (rounded to the nearest m). Every grid is limited to 1 <= m <= n_max // 4, beyond
    which the Allan deviation has too few degrees of freedom to mean anything.
    """
    if not rate_hz > 0:
        raise FogmonError(f"sample rate must be > 0 Hz, got {rate_hz}")
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
            raise FogmonError(f"taus must be 'octave', 'decade', 'all', an int per decade or tau values in s, got {taus!r}")
    elif isinstance(taus, (int, np.integer)) and not isinstance(taus, bool):
        if taus < 1:
            raise FogmonError(f"taus per decade must be >= 1, got {taus}")
        k = np.arange(int(np.floor(np.log10(m_max) * taus)) + 1)
        m = np.round(10.0 ** (k / taus))
    else:
        tau_s = np.atleast_1d(np.asarray(taus, dtype=np.float64))
        if tau_s.size == 0 or not np.all(np.isfinite(tau_s)) or np.any(tau_s <= 0):
            raise FogmonError("tau values must be finite and > 0 s")
        m = np.maximum(np.round(tau_s * rate_hz), 1)
    m = np.unique(np.asarray(m, dtype=np.int64))
    return m[(m >= 1) & (m <= m_max)]
