"""fogmon's build: the package (pyproject.toml) and, when it can be built, the extension
module of its numba kernels compiled ahead of time (fogmon/jit.py, ``build_ahead_of_time``),
so that no run compiles them. Without it (no C compiler, numba.pycc unavailable) the
install goes on with a warning and the first run compiles the kernels."""
import os
import shutil
import sys
import tempfile

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

AOT_MODULE = "fogmon._kernels_aot"   # fogmon.jit.AOT_MODULE


class BuildKernels(build_ext):
    """Builds fogmon._kernels_aot with numba.pycc (no C sources of its own); drops it,
    with a warning, when that fails."""

    def run(self):
        inplace, self.inplace = self.inplace, 0
        path = self.get_ext_fullpath(AOT_MODULE)   # in the build folder (copied in place when editable)
        self.inplace = inplace
        cache = tempfile.mkdtemp(prefix="fogmon-build-")   # numba's cache of the build: not the source tree's
        try:
            os.makedirs(os.path.dirname(path), exist_ok=True)
            os.environ["NUMBA_CACHE_DIR"] = cache
            sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
            from fogmon import jit

            jit.build_ahead_of_time(path)
        except Exception as e:  # noqa: BLE001 - any failure: the package works without it
            self.warn(f"fogmon: the kernels were not compiled ahead of time ({type(e).__name__}: {e}); "
                      f"the first run compiles them")
            self.extensions = []
        finally:
            shutil.rmtree(cache, ignore_errors=True)
        super().run()

    def build_extension(self, ext):
        pass   # built by run()


setup(ext_modules=[Extension(AOT_MODULE, sources=[])], cmdclass={"build_ext": BuildKernels})
