"""Exact chunking of a long recording (pure arithmetic on sample indices).

The streaming engine's windows end at sample indices k * hop + W - 1 (k = 0, 1, ...,
W the window and hop in samples, from the recording's first sample), and the noise type
behind the confidence bounds is refitted on windows k = 0, s, 2s, ... with s =
ceil(max(hop, W // 4) / hop) (fogmon.davar.batch.edf_rows). A chunk that owns windows
k0 .. k1 - 1, with k0 a multiple of s, is fed samples k0 * hop .. (k1 - 1) * hop + W - 1:
it overlaps the next chunk by W - hop samples (one window less one hop), its engine
emits exactly the windows of the single pass with the same noise types, and each
window is owned by one chunk. The last chunk also begins early enough (still on the
s * hop grid) to hold the last ``tail`` samples, which the whole-record fit uses."""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Chunk:
    """Chunk ``index`` (from 0) of a recording of ``n`` samples: it is fed samples
    ``feed_first`` .. ``feed_stop`` - 1, owns (emits) windows ``k_first`` .. ``k_stop`` - 1
    and counts samples ``own_first`` .. ``own_stop`` - 1 (the chunks' own ranges tile the
    recording); ``last``: it ends the recording (its run gives the whole-record fit)."""

    index: int
    feed_first: int
    feed_stop: int
    k_first: int
    k_stop: int
    own_first: int
    own_stop: int
    last: bool


def refit_period(window: int, hop: int) -> int:
    """Windows between two refits of the noise types (``s`` above)."""
    return math.ceil(max(hop, window // 4) / hop)


def plan_chunks(n: int, window: int, hop: int, chunk_samples: int, tail: int) -> list[Chunk]:
    """Chunks of about ``chunk_samples`` samples (at least one refit period of windows
    each) of a recording of ``n`` samples, windows of ``window`` and hops of ``hop``
    samples; the last chunk holds at least the last min(n, ``tail``) samples. One chunk
    when the recording is no longer than ``chunk_samples``."""
    if n < window:
        raise ValueError("the recording is shorter than one window")
    n_windows = (n - window) // hop + 1
    s = refit_period(window, hop)
    per = max(s, (max(chunk_samples - window, 0) // hop) // s * s)
    if n <= chunk_samples:
        per = n_windows
    out = []
    for j, k0 in enumerate(range(0, n_windows, per)):
        k1 = min(k0 + per, n_windows)
        last = k1 == n_windows
        feed_first = k0 * hop
        if last:
            grid = s * hop
            feed_first = min(feed_first, max(0, n - tail) // grid * grid)
        out.append(Chunk(j, feed_first, n if last else (k1 - 1) * hop + window, k0, k1,
                         0 if j == 0 else k0 * hop, n if last else k1 * hop, last))
    return out
