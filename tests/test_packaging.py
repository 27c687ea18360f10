"""pyproject.toml's runtime dependencies are what the package imports: every one is
imported somewhere in fogmon/ (at any level, also inside functions), and the packages
only tests and benchmarks use (allantools) are not runtime dependencies (issue 31)."""
import ast
import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: distribution name -> the module it installs, where they differ; dask comes with distributed
MODULE = {"pyserial": "serial", "python-can": "can", "rerun-sdk": "rerun", "tomli-w": "tomli_w",
          "PyWavelets": "pywt", "dask": "distributed"}


def imported_modules() -> set[str]:
    found = set()
    for path in (ROOT / "fogmon").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
    return found


def test_runtime_dependencies_are_the_packages_fogmon_imports():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    names = [re.split(r"[<>=~!\[ ;]", d, maxsplit=1)[0] for d in project["dependencies"]]
    imported = imported_modules()
    assert [n for n in names if MODULE.get(n, n) not in imported] == []
    assert "allantools" not in names and "allantools" not in imported
    assert any(d.startswith("allantools") for d in project["optional-dependencies"]["test"])
