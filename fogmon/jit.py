"""fogmon's numba kernels: compiled once, for every configuration.

Every numba kernel is made by ``kernel``: nopython and cached on disk (``cache=True``).

- A kernel called from Python declares its argument types (``kernel((F1, B1))``) and
  its call sites pass exactly these (C-contiguous, writable arrays of the declared
  dtypes, Python or numpy scalars), so one compiled version serves every command and
  option (tests/test_jit.py runs the configurations and checks that no other version
  is made).
- A kernel called only from other kernels (no Python entry point) is compiled for the
  types at its call sites, never for a constant's value: numba would make one version per literal argument
  (``f(x, 0)`` and ``f(x, n)``, ``g(.., True)`` and ``g(.., b)``), each costing the
  kernel's whole compile.
- When a process compiles a declared kernel (not in the cache), it then compiles every
  declared kernel the cache lacks (``warm_up``; a progress line on stderr in the fogmon
  program), so the first run of any command compiles for all of them and no later
  command or option compiles again (a warm run pays nothing for this). Not when that
  kernel could not be saved (the cache is unusable): the run compiles only what it
  needs, as numba does; nor when the kernels compiled ahead of time (below) serve the
  declared kernels (a call with other argument types compiles that version only).

A kernel's cache entry is keyed by the sources of every kernel module (``_sources_digest``)
besides numba's own key (the function's bytecode and its file's time stamp): numba
keeps a kernel compiled with the code of kernels it calls in other modules, so an edit
there alone (a ``git pull`` into an editable install) would load stale machine code.

A numba cache that cannot be read or written (corrupt files, an install directory
without write access, ``NUMBA_CACHE_DIR`` pointing nowhere usable) costs a compile in
memory and one FogmonWarning, never the run.

Ahead of time: installing fogmon builds the declared kernels into one extension module,
``fogmon._kernels_aot`` (setup.py, ``build_ahead_of_time``: numba.pycc, for the installing
machine's CPU), so that no run compiles them. A call of a declared kernel from Python
goes to that module's function when the module imports and its ``fingerprint`` matches
this process's (the kernel modules' sources, numba's and numpy's versions, the CPU name
and features: an edited kernel, an upgraded library or a copy on another CPU uses the
numba path above); a kernel calling a declared kernel always uses numba's. An install
that could not build it (no C compiler, numba.pycc gone) warns and works as above.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib
import importlib.util
import os
import sys
import time
import warnings
from collections.abc import Callable

import llvmlite.binding as llvm  # type: ignore[import-untyped]
import numba
import numpy as np
from numba import types
from numba.core import caching, codegen

from fogmon import startup
from fogmon.errors import FogmonWarning

#: the modules that define kernels (``warm_up`` imports them; tests/test_jit.py checks the list)
KERNEL_MODULES = ("fogmon.davar.kernels", "fogmon.davar.window_stats", "fogmon.davar.running_sums",
                  "fogmon.davar.scoring", "fogmon.davar.profile", "fogmon.motion")

# argument types of the declarations: scalars, C-contiguous 1-4 dimensional arrays
F8, I8, BOOL, NONE = types.float64, types.int64, types.boolean, types.none
F1, F2, F3, F4 = (types.Array(F8, d, "C") for d in (1, 2, 3, 4))
I1, I2 = types.Array(I8, 1, "C"), types.Array(I8, 2, "C")
B1 = types.Array(BOOL, 1, "C")

#: False: no warm-up; each kernel is compiled when first needed (numba's own way)
warm_up_on_first_use = True
#: False: declared kernels run numba's code even when the ahead-of-time module is built
use_ahead_of_time = True
#: the extension module setup.py builds (``build_ahead_of_time``)
AOT_MODULE = "fogmon._kernels_aot"

_declared: list[tuple[numba.core.registry.CPUDispatcher, tuple]] = []
_warmed_up = False


class Kernel:
    """A declared kernel as Python calls it: the ahead-of-time module's function when
    ``ahead_of_time`` has it, else the numba dispatcher (``dispatcher``; every attribute
    not defined here is the dispatcher's, and other kernels call the dispatcher)."""

    def __init__(self, dispatcher, signature: tuple):
        self.dispatcher = dispatcher
        self._accepts = tuple(_accepts(t) for t in signature)
        self._call: Callable | None = None
        functools.update_wrapper(self, dispatcher.py_func)

    def __call__(self, *args):
        if self._call is None:
            module = ahead_of_time()
            self._call = getattr(module, self.dispatcher.py_func.__name__, self.dispatcher) if module else \
                self.dispatcher
        if self._call is not self.dispatcher and not (
                len(args) == len(self._accepts) and all(ok(a) for ok, a in zip(self._accepts, args, strict=False))):
            return self.dispatcher(*args)   # not the declared types: numba's path (the module's would misread them)
        return self._call(*args)

    def __getattr__(self, name: str):
        return getattr(self.dispatcher, name)

    def __reduce__(self):
        return _kernel_named, (self.dispatcher.py_func.__module__, self.dispatcher.py_func.__name__)


def _accepts(t) -> Callable[[object], bool]:
    """Whether a Python argument has the numba type ``t`` of a declaration (or converts to
    it as numba's dispatcher would, for scalars): the ahead-of-time code checks only an
    array's item size."""
    if isinstance(t, types.Array):
        dtype, ndim = numba.np.numpy_support.as_dtype(t.dtype), t.ndim
        return lambda a: (isinstance(a, np.ndarray) and a.dtype == dtype and a.ndim == ndim and a.flags.c_contiguous
                          and a.flags.writeable)
    if isinstance(t, types.Tuple | types.UniTuple):
        items = tuple(_accepts(u) for u in t.types)
        return lambda a: isinstance(a, tuple) and len(a) == len(items) and all(
            ok(u) for ok, u in zip(items, a, strict=False))
    if isinstance(t, types.Boolean):
        return lambda a: isinstance(a, bool | np.bool_)
    if isinstance(t, types.Integer):
        return lambda a: isinstance(a, int | np.integer) and not isinstance(a, bool)
    if isinstance(t, types.Float):
        return lambda a: isinstance(a, float | int | np.floating | np.integer) and not isinstance(a, bool)
    return lambda a: False


def _kernel_named(module: str, name: str) -> Kernel:
    return getattr(importlib.import_module(module), name)


def kernel(*signatures: tuple, **options) -> Callable:
    """Decorator: ``numba.njit(cache=True, **options)`` (e.g. ``inline="always"``,
    ``fastmath``, ``error_model``) with the argument types ``signatures`` (tuples of
    numba types, one per version): a ``Kernel``. Without them the kernel is called only
    from other kernels: the dispatcher, with no Python entry point (numba's CPython and
    C wrappers, a compile of their own per kernel)."""
    def wrap(fn):
        if not signatures and "inline" not in options:
            options.update(no_cpython_wrapper=True, no_cfunc_wrapper=True)
        disp = numba.njit(cache=True, **options)(fn)
        _key_by_sources(disp)
        template = disp.get_call_template

        def get_call_template(args, kws):  # a call from another kernel: types, not constants
            return template(tuple(types.unliteral(a) for a in args),
                            {k: types.unliteral(v) for k, v in kws.items()})
        disp.get_call_template = get_call_template
        if signatures:
            _declared.append((disp, tuple(tuple(s) for s in signatures)))
            compile_for_args = disp._compile_for_args

            def first_compile_warms_up(*args, **kws):  # numba calls it when no version in memory matches
                global _warmed_up
                t0 = time.process_time()
                misses = sum(disp.stats.cache_misses.values())
                out = compile_for_args(*args, **kws)
                if (not _warmed_up and warm_up_on_first_use and ahead_of_time() is None
                        and sum(disp.stats.cache_misses.values()) > misses):
                    _warmed_up = True   # this kernel was compiled: so, once, are the others the cache lacks
                    if is_cached(disp, tuple(disp.typeof_pyval(a) for a in args)):  # (else the cache is unusable)
                        warm_up(_progress_line(t0))
                return out
            disp._compile_for_args = first_compile_warms_up
            return Kernel(disp, signatures[0]) if len(signatures) == 1 else disp
        return disp
    return wrap


@functools.cache
def _sources_digest() -> str:
    """SHA-256 of the source files of fogmon.jit and every kernel module (read once, when
    the first kernel looks into the cache: after KERNEL_MODULES is final)."""
    h = hashlib.sha256()
    for name in (__name__, *KERNEL_MODULES):
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.origin:
            with open(spec.origin, "rb") as fh:
                h.update(fh.read())
    return h.hexdigest()


def _key_by_sources(disp) -> None:
    """``disp``'s cache entries keyed also by ``_sources_digest``."""
    cache = getattr(disp, "_cache", None)
    if isinstance(cache, caching.Cache):
        key = cache._index_key
        cache._index_key = lambda sig, codegen: (*key(sig, codegen), _sources_digest())  # type: ignore[method-assign]


def declared() -> list[tuple[str, numba.core.registry.CPUDispatcher, tuple]]:
    """(qualified name, dispatcher, argument types) of every declared kernel version
    (the kernel modules imported)."""
    for name in KERNEL_MODULES:
        importlib.import_module(name)
    return [(f"{d.py_func.__module__}.{d.py_func.__name__}", d, s) for d, sigs in _declared for s in sigs]


def is_cached(disp, signature: tuple) -> bool:
    """The numba cache holds ``disp``'s version for these argument types (its index is
    read, nothing is loaded); True when the dispatcher does not cache."""
    cache = getattr(disp, "_cache", None)
    if not isinstance(cache, caching.Cache):
        return True
    try:
        key = cache._index_key(tuple(signature), disp.targetctx.codegen())
        return key in cache._cache_file._load_index()
    except Exception:  # noqa: BLE001 - an unreadable index: not cached
        return False


def warm_up(report: Callable[[int, int, str | None], None] | None = None) -> int:
    """Compile every declared kernel version that the numba cache lacks; returns how many
    were compiled. ``report(done, total, name)`` before each (``name`` None at the end).
    Stops after a version that was not saved (the cache is unusable: compiling ahead
    would be lost)."""
    todo = [(name, d, s) for name, d, s in declared() if not is_cached(d, s)]
    for i, (name, d, s) in enumerate(todo):
        if report:
            report(i, len(todo), name.rsplit(".", 1)[1])
        d.compile(s)
        if not is_cached(d, s):
            todo = todo[:i + 1]
            break
    if report and todo:
        report(len(todo), len(todo), None)
    return len(todo)


def fingerprint() -> int:
    """What the ahead-of-time code depends on, as a 63-bit integer: the kernel modules'
    sources, numba's and numpy's versions, the CPU's name and features (numba's own
    settings of them, ``NUMBA_CPU_NAME``, ``NUMBA_CPU_FEATURES``, when given)."""
    cpu = getattr(numba.config, "CPU_NAME", None) or llvm.get_host_cpu_name()
    features = codegen.get_host_cpu_features()   # (NUMBA_CPU_FEATURES when given)
    text = "\n".join((_sources_digest(), numba.__version__, np.__version__, cpu, features))
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little") >> 1


@functools.cache
def ahead_of_time():
    """The ahead-of-time module (``AOT_MODULE``) when it is built, imports and was built
    from this process's ``fingerprint``, else None (then numba compiles, as without it)."""
    if not use_ahead_of_time:
        return None
    declared()   # every kernel module imported: their sources are final
    try:
        module = importlib.import_module(AOT_MODULE)
        return module if module.fingerprint() == fingerprint() else None
    except Exception:  # noqa: BLE001 - not built, or built for other libraries: numba's path
        return None


def build_ahead_of_time(path: str) -> None:
    """Compile every declared kernel (each version's signature, numba's return type) into
    the extension module file ``path`` (``AOT_MODULE``, for this machine's CPU) with
    numba.pycc; the module's ``fingerprint()`` returns this process's. setup.py calls it
    (needs a C compiler; numba compiles the kernels first, as a warm-up would)."""
    from numba.pycc import CC

    cc = CC(AOT_MODULE.rsplit(".", 1)[1], source_module=sys.modules[__name__])
    cc.output_dir, cc.output_file = os.path.split(os.path.abspath(path))
    cc.target_cpu = "host"
    # the CPU's own features, as numba's JIT targets them (pycc takes the CPU model's: a virtual
    # machine may lack some of them)
    codegen.AOTCPUCodegen._customize_tm_features = lambda self: self._get_host_cpu_features()  # type: ignore
    names = set()
    for name, d, sig in declared():
        short = name.rsplit(".", 1)[1]
        if short in names:
            raise RuntimeError(f"two declared kernels (or versions) named {short}: one entry per name")
        names.add(short)
        d.compile(sig)
        args = ", ".join(f"a{i}" for i in range(len(sig)))
        scope = {"k": d}
        exec(f"def {short}({args}):\n    return k({args})\n", scope)   # the dispatcher's code, its options
        cc.export(short, next(s for s in d.nopython_signatures if s.args == sig))(scope[short])
    value = fingerprint()
    cc.export("fingerprint", types.int64())(lambda: value)
    cc.compile()


def c_array(a, dtype) -> np.ndarray:
    """``a`` as a C-contiguous, writable array of ``dtype``: the form of a declared
    kernel's array argument (copied only when it is not: a read-only or strided view)."""
    a = np.ascontiguousarray(a, dtype=dtype)
    return a if a.flags.writeable else a.copy()


def _progress_line(t0: float) -> Callable[[int, int, str | None], None] | None:
    """The warm-up's progress on stderr, in the fogmon program only (a library user's
    process prints nothing): one line updated in place on a terminal, else a line at the
    start and one at the end (with the CPU time since ``t0``, ``time.process_time``)."""
    if not startup.is_own_process():
        return None
    tty = sys.stderr.isatty()

    def report(done: int, total: int, name: str | None) -> None:
        head = "fogmon: compiling the numba kernels once (later runs load them from the cache)"
        if name is None:
            line = f"{head}: done in {time.process_time() - t0:.0f} CPU s"
        elif tty:
            line = f"{head}: {done + 1}/{total} {name}"
        elif done == 0:
            line = f"{head} ..."
        else:
            return
        print(("\r\x1b[K" if tty else "") + line, end="\n" if name is None or not tty else "", file=sys.stderr,
              flush=True)
    return report


def _tolerate_unusable_cache() -> None:
    """numba's guard around cache I/O (which forgives only EACCES, only on Windows) is
    widened to every error, reported once per process as a FogmonWarning. A cache from
    other sources is ignored by numba itself (it checks the source file's stamp)."""
    if getattr(caching.Cache, "_fogmon_tolerant", False):
        return
    warned: list[Exception] = []

    @contextlib.contextmanager
    def guard(self):
        try:
            yield
        except Exception as e:  # noqa: BLE001 - any cache failure: compile in memory instead
            if not warned:
                warned.append(e)
                warnings.warn(f"numba cache unusable ({type(e).__name__}: {e}); kernels are compiled in "
                              f"memory for this run", FogmonWarning, stacklevel=1)
    caching.Cache._guard_against_spurious_io_errors = guard  # type: ignore[method-assign]
    caching.Cache._fogmon_tolerant = True  # type: ignore[attr-defined]


_tolerate_unusable_cache()
