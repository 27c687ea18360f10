"""The fogmon program's start-up: the cyclic garbage collector paused while libraries load,
and pyarrow's arrays made without importing pandas (``arrow_without_pandas``).

Loading numpy, numba (its registries, scipy.linalg), Rerun and the numba kernels
allocates a few hundred thousand objects that live as long as the process, and every
collection on the way scans them again: 0.3 CPU s of the demo replay (then ~3.5 CPU s).
``loading()`` pauses the collector over such a phase, then freezes what is alive
(``gc.freeze``: left out of every later collection); objects freed by reference counting
are freed as always. Only in the program's own process (``own_process``): in a program
that imports fogmon the collector is left alone, since a freeze would keep the cyclic
garbage it has not collected yet for good.
"""
from __future__ import annotations

import gc
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from importlib.machinery import ModuleSpec

#: A phase longer than this (CPU s) compiled numba kernels (tens of s on a first run):
#: its garbage (~280 k objects, ~50 MB on the demo replay) is collected before the
#: freeze, which costs ~0.4 s there; a phase that loaded cached kernels leaves ~10 k.
COMPILED_CPU_S = 5.0

_own_process = False


def own_process() -> None:
    """Called by the ``fogmon`` program (``fogmon.cli.main`` run as the program): from now
    on ``loading()`` phases pause the collector and freeze."""
    global _own_process
    _own_process = True


def is_own_process() -> bool:
    """This is the ``fogmon`` program's own process (see ``own_process``)."""
    return _own_process


@contextmanager
def loading() -> Iterator[None]:
    """In the program's own process: no cyclic garbage collection inside; at the end every
    live object is frozen and the collector is back as it was (nested phases: each freezes
    at its end, the collector comes back at the end of the outermost). Elsewhere nothing
    changes."""
    if not _own_process:
        yield
        return
    enabled = gc.isenabled()
    gc.disable()
    t0 = time.process_time()
    try:
        yield
    finally:
        if time.process_time() - t0 > COMPILED_CPU_S:
            gc.collect()
        gc.freeze()
        if enabled:
            gc.enable()


class _NoPandas:
    """A meta-path finder for which pandas cannot be imported."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> ModuleSpec | None:
        if name == "pandas":
            raise ImportError("pandas is not imported for pyarrow (fogmon.startup.arrow_without_pandas)")
        return None


def arrow_without_pandas() -> None:
    """In the program's own process, before Rerun's first pyarrow array: pyarrow's first
    ``pa.array`` call imports pandas (0.3-0.45 CPU s) only to ask whether its input is a
    pandas object; fogmon never hands it one. This makes that first question find no
    pandas: later calls of that kind take it as absent, and what needs pandas itself
    (``to_pandas``, ``Table.from_pandas``) imports it then, as always. Nothing changes
    elsewhere, or once pandas is imported."""
    if not _own_process or "pandas" in sys.modules:
        return
    import pyarrow as pa

    finder = _NoPandas()
    sys.meta_path.insert(0, finder)
    try:
        pa.array([0])
    finally:
        sys.meta_path.remove(finder)
