"""On-disk cache of bootstrap results: one .npy file per key (a SHA-256 of everything
the result depends on) under $XDG_CACHE_HOME/fogmon or ~/.cache/fogmon. A missing,
corrupt or mismatched file is rebuilt, never fatal; a folder that cannot be written
just skips caching (the caller is told why)."""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile

import numpy as np

#: Bumped whenever what is cached changes meaning (invalidates every older file).
FORMAT = "modelband-1"


def default_dir() -> str:
    """$XDG_CACHE_HOME/fogmon, else ~/.cache/fogmon."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "fogmon")


def key(spec: dict) -> str:
    """Hex SHA-256 of ``spec`` (JSON-serialisable) and the cache format."""
    text = json.dumps({"format": FORMAT, **spec}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _path(folder: str, k: str) -> str:
    return os.path.join(folder, f"{FORMAT}-{k}.npy")


def load(folder: str, k: str, shape: tuple[int, ...]) -> np.ndarray | None:
    """The cached float64 array of key ``k`` if it is readable and has ``shape``, else None."""
    try:
        a = np.load(_path(folder, k), allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return None
    if a.dtype != np.float64 or a.shape != shape or np.isnan(a).any():
        return None
    return a


def save(folder: str, k: str, a: np.ndarray) -> str:
    """Write ``a`` under key ``k`` atomically (temporary file, then rename); returns a
    short status: where it was cached, or why it was not."""
    tmp = None
    try:
        os.makedirs(folder, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".npy", dir=folder)
        with os.fdopen(fd, "wb") as fh:
            np.save(fh, np.asarray(a, dtype=np.float64), allow_pickle=False)
        os.replace(tmp, _path(folder, k))
        tmp = None
        return f"built and cached in {folder}"
    except OSError as e:
        return f"built, not cached ({folder}: {e.strerror or e})"
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
