"""The default DAVAR window of a run (the window policy's pure part): a power of two of
samples, a quarter of the record within bounds, or a fixed length live. The pipeline
checks a window against the run (fogmon.pipeline.config.window_and_hop); the console
summary suggests one."""
from __future__ import annotations

import math

#: Default window bounds in samples (the window is a power of two inside these).
MIN_WINDOW_SAMPLES = 2**10
MAX_WINDOW_SAMPLES = 2**20
#: Live default window in samples (65.5 s at 1 kHz, 655 s at 100 Hz).
LIVE_WINDOW_SAMPLES = 2**16


def default_window_s(sample_rate_hz: float, n_samples: int | None) -> float:
    """Default window in s: for a record of ``n_samples`` a quarter of it rounded down to a
    power of two of samples (within MIN..MAX_WINDOW_SAMPLES, never longer than the record);
    live (``n_samples`` None) LIVE_WINDOW_SAMPLES."""
    if n_samples is None:
        return LIVE_WINDOW_SAMPLES / sample_rate_hz
    quarter = max(n_samples // 4, 1)
    n = 2 ** int(math.floor(math.log2(quarter)))
    n = min(max(n, MIN_WINDOW_SAMPLES), MAX_WINDOW_SAMPLES, n_samples)
    return n / sample_rate_hz
