"""fogmon.jit: every kernel compiled once for every configuration (issue 33): the call
sites pass the declared argument types, a kernel called with a constant is not
compiled again per value, a process that compiles a declared kernel also compiles every
declared kernel the cache lacks (not when the cache cannot keep them); the module compiled
ahead of time, when built, serves the declared kernels with numba's results and is not used
when it is stale or the arguments are not the declared types."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import fogmon
from fogmon import jit

ROOT = Path(fogmon.__file__).resolve().parent


def test_kernel_modules_lists_every_module_with_kernels():
    found = set()
    for path in ROOT.rglob("*.py"):
        if re.search(r"^@kernel\(", path.read_text(encoding="utf-8"), re.M):
            found.add(".".join(("fogmon", *path.relative_to(ROOT).with_suffix("").parts)))
    assert found == set(jit.KERNEL_MODULES)


#: the engines in every mode, with gaps, huge and large samples, read-only and float32
#: input, the fits and the motion gate; then the versions each declared kernel has
_CONFIGURATIONS = """
import numpy as np
from fogmon import jit
jit.use_ahead_of_time = False   # numba's versions (the module compiled ahead of time has the same declarations)
from fogmon.davar.batch import dadev, oadev
from fogmon.davar.fit import fit_noise
from fogmon.davar.streaming import StreamingDadev
from fogmon.motion import find_motion
from fogmon.motion_gate import MotionGate

rng = np.random.default_rng(1)
y = 10.0 + rng.standard_normal(20000)
y[3000:3010] = np.nan
y[7000] = 1e9       # huge
y[9000] = 1e6       # large
ro = y.copy()
ro.flags.writeable = False
for hop_s, alpha in ((0.01, None), (0.01, 0), (0.16, None), (0.64, 0), (10.24, None)):
    e = StreamingDadev(100.0, 20.48, hop_s=hop_s, alpha=alpha)
    for i in range(0, len(y), 3000):
        r = e.push(ro[i:i + 3000])
        if len(r):  # adev formed when read: one row, then all (and the interval)
            r.window(len(r) - 1), r.lo_dph
    e.advance(y[:5].astype(np.float32))
    e.push(y[:3])
    e.current()
fit_noise(dadev(ro, 100.0, 20.48, 5.12))
fit_noise(dadev(y.astype(np.float32), 100.0, 20.48, 0.5, taus="all"))
fit_noise(oadev(ro[::2], 100.0))
t = np.arange(len(y)) / 100.0
z = np.where(np.isfinite(y), y, 10.0)
z[12000:12200] += 500.0
find_motion(t, z, np.isfinite(y), 100.0)
g = MotionGate(100.0)
for i in range(0, len(y), 1000):
    g.push(t[i:i + 1000], z[i:i + 1000], np.ones(1000, bool))
g.flush()
allowed = {}
for name, d, sig in jit.declared():
    allowed.setdefault(name, (d, set()))[1].add(tuple(sig))
for name, (d, sigs) in allowed.items():
    extra = set(d.signatures) - sigs
    print(name, len(d.signatures), "EXTRA " + repr(extra) if extra else "")
"""


def test_every_configuration_runs_the_declared_kernel_versions():
    p = subprocess.run([sys.executable, "-c", _CONFIGURATIONS], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "EXTRA" not in p.stdout, p.stdout
    used = {line.split()[0] for line in p.stdout.splitlines() if line.split()[1] != "0"}
    assert {"fogmon.davar.running_sums.stream_update", "fogmon.davar.kernels.stream_record",
            "fogmon.davar.kernels.window_sums_exact", "fogmon.davar.profile.fit_full",
            "fogmon.motion._block_means"} <= used, p.stdout


_DUMMY = '''
from fogmon.jit import F1, I8, kernel


@kernel()
def helper(x, k):
    return x[k]


@kernel((F1,))
def first(x):
    return helper(x, 0) + helper(x, x.shape[0] - 1)


@kernel((F1, I8))
def second(x, k):
    return 2.0 * x[k]
'''

_RUN = """
import sys
import numpy as np
sys.path.insert(0, {tmp!r})
from fogmon import jit, startup
startup.own_process()
jit.use_ahead_of_time = False
jit.KERNEL_MODULES = ("dummy_kernels",)
import dummy_kernels as d
print(d.first(np.arange(3.0)))
print(jit.is_cached(d.second, (jit.F1, jit.I8)), len(d.second.signatures), len(d.helper.signatures),
      "Literal" in repr(d.helper.signatures), sum(d.first.stats.cache_misses.values()))
"""


def _run(tmp: Path, cache: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", _RUN.format(tmp=str(tmp))], capture_output=True, text=True,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(cache)})


def test_a_compile_warms_up_every_declared_kernel_once(tmp_path):
    (tmp_path / "dummy_kernels.py").write_text(textwrap.dedent(_DUMMY))
    cache = tmp_path / "cache"
    p = _run(tmp_path, cache)
    assert p.returncode == 0, p.stderr
    # second() was never called, yet compiled and cached; helper() once for a constant and a variable
    assert p.stdout.split() == ["2.0", "True", "1", "1", "False", "1"]
    assert re.search(r"compiling the numba kernels once.*: done in \d+ CPU s", p.stderr), p.stderr
    p = _run(tmp_path, cache)   # the next run loads them: no compile, no progress line
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["2.0", "True", "0", "0", "False", "0"]
    assert "compiling" not in p.stderr


def test_no_warm_up_when_the_cache_cannot_keep_kernels(tmp_path):
    (tmp_path / "dummy_kernels.py").write_text(textwrap.dedent(_DUMMY))
    cache = tmp_path / "cache"
    assert _run(tmp_path, cache).returncode == 0
    for f in cache.rglob("*"):
        if f.is_file():
            f.write_text("garbage")   # a corrupt cache: neither read nor written
    p = _run(tmp_path, cache)
    assert p.returncode == 0, p.stderr
    # first() compiled in memory, second() not compiled ahead: it would be lost
    assert p.stdout.split() == ["2.0", "False", "0", "1", "False", "1"]
    assert p.stderr.count("FogmonWarning: numba cache unusable") == 1


_CALLEE = '''
from fogmon.jit import kernel


@kernel()
def step(x):
    return x + {inc}
'''

_CALLER = '''
from fogmon.jit import F8, kernel
import dummy_callee


@kernel((F8,))
def outer(x):
    return dummy_callee.step(x)
'''

_RUN_CALLER = """
import sys
sys.path.insert(0, {tmp!r})
from fogmon import jit
jit.use_ahead_of_time = False
jit.KERNEL_MODULES = ("dummy_callee", "dummy_caller")
import dummy_caller
print(dummy_caller.outer(1.0))
"""


def test_an_edit_of_a_called_kernel_in_another_module_is_not_served_from_the_cache(tmp_path):
    """numba keys a cached kernel by its own file only: the caller compiled with the old
    callee would be loaded after an edit of the callee's module (a git pull into an
    editable install). fogmon.jit keys every entry by all kernel modules' sources."""
    (tmp_path / "dummy_caller.py").write_text(textwrap.dedent(_CALLER))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    out = []
    for inc in (1.0, 2.0):
        (tmp_path / "dummy_callee.py").write_text(textwrap.dedent(_CALLEE.format(inc=inc)))
        p = subprocess.run([sys.executable, "-c", _RUN_CALLER.format(tmp=str(tmp_path))], capture_output=True,
                           text=True, env=env)
        assert p.returncode == 0, p.stderr
        out.append(p.stdout.strip())
    assert out == ["2.0", "3.0"]


_AHEAD = """
import numpy as np
from fogmon import jit
from fogmon.davar.batch import dadev
from fogmon.davar.fit import fit_noise
from fogmon.davar.kernels import reference_level

jit.use_ahead_of_time = {aot}
rng = np.random.default_rng(2)
y = 5.0 + rng.standard_normal(40000) + np.cumsum(rng.standard_normal(40000)) * 1e-3
y[1000:1020] = np.nan
f = fit_noise(dadev(y, 100.0, 81.92, 20.48))
print([np.asarray(getattr(c, k)).tolist() for c in f.coefficients().values() for k in ("value", "lo", "hi", "upper")])
strided = np.arange(10.0)[::2]   # not the declared C-contiguous array: numba's path, not the module's
print(reference_level(strided, np.ones(5, bool)), len(reference_level.dispatcher.signatures))
print(jit.ahead_of_time() is not None)
"""


def test_the_module_compiled_ahead_of_time_gives_numbas_results():
    if jit.ahead_of_time() is None:
        pytest.skip("fogmon._kernels_aot is not built (or stale) in this install")
    out = [subprocess.run([sys.executable, "-c", _AHEAD.format(aot=aot)], capture_output=True, text=True)
           for aot in (True, False)]
    assert all(p.returncode == 0 for p in out), out[0].stderr + out[1].stderr
    with_aot, with_numba = (p.stdout.splitlines() for p in out)
    assert with_aot[0] == with_numba[0]   # every coefficient and limit, bit for bit
    # the strided array compiled numba's version for it (beside the declared one on numba's path)
    assert (with_aot[1], with_numba[1]) == ("4.0 1", "4.0 2")
    assert (with_aot[2], with_numba[2]) == ("True", "False")


def test_a_stale_module_compiled_ahead_of_time_is_not_used(monkeypatch):
    if jit.ahead_of_time() is None:
        pytest.skip("fogmon._kernels_aot is not built (or stale) in this install")
    monkeypatch.setattr(jit, "_sources_digest", lambda: "edited")   # a kernel module edited after the build
    jit.ahead_of_time.cache_clear()
    try:
        assert jit.ahead_of_time() is None
    finally:
        monkeypatch.undo()
        jit.ahead_of_time.cache_clear()
