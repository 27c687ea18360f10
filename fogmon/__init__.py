"""fogmon: real-time streaming monitor for fiber-optic gyroscopes.

Public API (units in every name: deg/h for rate, s for time, IEEE-952 units for
coefficients)::

    fogmon.oadev(rate_dph, sample_rate_hz, taus="octave")          -> AdevResult
    fogmon.dadev(rate_dph, sample_rate_hz, window_s, hop_s=None)   -> DadevResult
        both with exclude_motion=True: platform motion kept out as `fogmon replay`
        does (fogmon.motion; False analyses every sample, as --keep-motion)
    fogmon.StreamingDadev(sample_rate_hz, window_s, taus="octave") -> ring-buffer updater
    fogmon.fit_noise(result)                                -> IEEE-952 Q, N, B, K, R
    fogmon.adev_from_curve(tau_s, adev_dph, n_terms=...)    -> (AdevResult, assumptions)
                                                               of another tool's curve
    fogmon.tau_grid(sample_rate_hz, n_max, taus)                   -> averaging factors m
    fogmon.read_replay_log(path) / write_replay_log(...)    -> Recording I/O

Names are imported lazily so that ``fogmon --help`` starts fast.
"""
from __future__ import annotations

import importlib

__version__ = "0.1.0"

_LAZY = {
    "oadev": "fogmon.api",
    "dadev": "fogmon.api",
    "AdevResult": "fogmon.davar.result",
    "DadevResult": "fogmon.davar.result",
    "StreamingDadev": "fogmon.davar.streaming",
    "fit_noise": "fogmon.davar.fit",
    "NoiseFit": "fogmon.davar.fit",
    "adev_from_curve": "fogmon.davar.curve",
    "tau_grid": "fogmon.davar.taus",
    "Block": "fogmon.block",
    "Event": "fogmon.block",
    "Recording": "fogmon.formats.recording",
    "read_replay_log": "fogmon.formats.replay_log",
    "write_replay_log": "fogmon.formats.replay_log",
    "FogmonError": "fogmon.errors",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'fogmon' has no attribute {name!r}")
    value = getattr(importlib.import_module(mod), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
