"""The import picture of fogmon, counting every import at any level (inside functions
too): no cycle; packages in layers, at most two arrows from a lower layer to a higher
one; library code (everything outside fogmon/cli) never imports fogmon.cli nor
argparse; every module imports alone in a fresh interpreter, and the pipeline and the
sinks import in either order; no test module imports another."""
from __future__ import annotations

import ast
import pkgutil
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

import fogmon

ROOT = Path(fogmon.__file__).resolve().parent
#: every module but the entry point (``python -m fogmon`` runs the command when imported)
MODULES = sorted(m.name for m in pkgutil.walk_packages([str(ROOT)], prefix="fogmon.") if m.name != "fogmon.__main__")


def _imports(*names: str) -> subprocess.CompletedProcess:
    code = "import importlib\n" + "".join(f"importlib.import_module({n!r})\n" for n in names)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_every_module_imports_alone():
    """Each module in a fresh interpreter, one child process per module (one interpreter
    would hide a module that works only after another was imported). About 70 cold
    starts of numpy/scipy/numba: minutes on a loaded machine, so run with -m slow."""
    code = ("import subprocess, sys\nbad = []\n"
            f"for n in {MODULES!r}:\n"
            "    r = subprocess.run([sys.executable, '-c', f'import {n}'],\n"
            "                       capture_output=True, text=True)\n"
            "    if r.returncode: bad.append((n, r.stderr.strip().splitlines()[-1]))\n"
            "print(bad)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stdout + r.stderr


def test_pipeline_and_sinks_import_in_either_order():
    sinks = ("fogmon.sinks.base", "fogmon.sinks.console", "fogmon.sinks.rerun.sink", "fogmon.sinks.archive")
    for order in (("fogmon.pipeline", *sinks), (*sinks, "fogmon.pipeline")):
        r = _imports(*order)
        assert r.returncode == 0, r.stderr


def _every_import(path: Path, root: Path = ROOT) -> list[tuple[int, str]]:
    """(line, module) of every import in the file at ``path`` of the package at ``root``,
    at any level (inside functions and classes too), relative imports resolved, ``from m
    import n`` as m and m.n, and importlib.import_module / __import__ of a literal (or
    f-string) name."""
    name = ".".join(path.relative_to(root.parent).with_suffix("").parts)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    package = package.removesuffix(".__init__")
    out: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + ([node.module] if node.module else []))
            out.append((node.lineno, base))
            out += [(node.lineno, f"{base}.{a.name}") for a in node.names]
        elif isinstance(node, ast.Call) and node.args and (
                (isinstance(node.func, ast.Attribute) and node.func.attr == "import_module")
                or (isinstance(node.func, ast.Name) and node.func.id in ("import_module", "__import__"))):
            arg = node.args[0]
            if isinstance(arg, ast.JoinedStr) and arg.values and isinstance(arg.values[0], ast.Constant):
                arg = arg.values[0]
            if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                out.append((node.lineno, arg.value))
    return out


#: fogmon's packages and top-level modules in layers, lowest first: a module imports from
#: its own layer and the layers below (docs/architecture.md). ``fogmon`` is the package's
#: public API (it loads its names lazily), ``__main__`` runs the command.
LAYERS = [
    ("core", {"errors", "units", "block", "window", "stopping", "startup", "outputs", "jit"}),
    ("formats", {"formats"}),
    ("analysis", {"davar", "sim", "motion", "motion_gate", "phases", "api"}),
    ("sources", {"sources"}),
    ("sinks", {"sinks"}),
    ("explain", {"explain"}),
    ("methods", {"methods", "modelcheck"}),
    ("pipeline", {"pipeline"}),
    ("applications", {"export", "fleet"}),
    ("command", {"cli", "__main__", "fogmon"}),
]
#: arrows from a lower layer to a higher one the picture may have (issue 27)
MAX_UPWARD = 2


def _name(path: Path) -> str:
    return ".".join(path.relative_to(ROOT.parent).with_suffix("").parts).removesuffix(".__init__")


def _unit(module: str) -> str:
    """The package or top-level module of LAYERS ``module`` is in."""
    return module.split(".")[1] if "." in module else module


def _graph() -> dict[str, set[str]]:
    """fogmon module -> the fogmon modules its imports name, at any level: ``from m import
    n`` names m.n when that is a module (else m), ``import a.b`` names a.b."""
    modules = {_name(p) for p in ROOT.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for p in sorted(ROOT.rglob("*.py")):
        by_line: dict[int, set[str]] = defaultdict(set)
        for line, m in _every_import(p):
            while m and m not in modules:
                m = m.rpartition(".")[0]
            if m:
                by_line[line].add(m)
        name = _name(p)
        graph[name] = {m for found in by_line.values() for m in found
                       if m != name and not any(o.startswith(m + ".") for o in found)}
    return graph


def test_no_import_cycle():
    """Not even through an import inside a function (it runs later, but still ties the two
    modules to each other)."""
    graph = _graph()
    state: dict[str, int] = {}

    def visit(m: str, path: list[str]) -> None:
        if state.get(m) == 1:
            raise AssertionError("import cycle: " + " -> ".join(path[path.index(m):] + [m]))
        if state.get(m) == 2:
            return
        state[m] = 1
        for n in sorted(graph[m]):
            visit(n, path + [m])
        state[m] = 2

    for m in sorted(graph):
        visit(m, [])


def test_the_layers_hold_every_package_and_at_most_two_arrows_point_up():
    graph = _graph()
    layer = {unit: i for i, (_, units) in enumerate(LAYERS) for unit in units}
    assert sorted({_unit(m) for m in graph} - layer.keys()) == []          # a new package: give it a layer
    up: dict[tuple[str, str], list[str]] = defaultdict(list)
    for m, imported in sorted(graph.items()):
        for n in sorted(imported):
            if layer[_unit(m)] < layer[_unit(n)]:
                up[(_unit(m), _unit(n))].append(f"{m} -> {n}")
    assert len(up) <= MAX_UPWARD, "arrows up the layers:\n" + "\n".join(
        f"{a} -> {b}: {', '.join(e)}" for (a, b), e in sorted(up.items()))


def _library_files() -> list[Path]:
    """Every module outside fogmon/cli but the entry point (``python -m fogmon``)."""
    return [p for p in sorted(ROOT.rglob("*.py"))
            if p.relative_to(ROOT).parts[0] != "cli" and p.name != "__main__.py"]


def test_every_import_is_found_at_any_level(tmp_path):
    pkg = tmp_path / "fogmon" / "sub"
    pkg.mkdir(parents=True)
    (pkg / "m.py").write_text("def f():\n    from .. import cli\n    import argparse\n"
                              "    importlib.import_module(f'fogmon.cli.{x}')\n", encoding="utf-8")
    found = [m for _, m in _every_import(pkg / "m.py", tmp_path / "fogmon")]
    assert found == ["fogmon", "fogmon.cli", "argparse", "fogmon.cli."]


def test_library_code_never_imports_the_command_line_nor_argparse():
    """Library code gets plain parameters and option dataclasses (SourceOptions,
    PipelineConfig, explain's Options), never an argparse namespace: python-can's rule
    (argparse in can/cli.py only)."""
    bad = [f"{p.relative_to(ROOT.parent)}:{line}: imports {m}" for p in _library_files()
           for line, m in _every_import(p)
           if m == "argparse" or m.startswith("argparse.") or m == "fogmon.cli" or m.startswith("fogmon.cli.")]
    assert not bad, "\n".join(bad)


def test_library_code_does_not_import_the_command_line():
    r = _imports("fogmon.pipeline", "fogmon.sources.open", "fogmon.sinks.console", "fogmon.sinks.rerun.sink",
                 "fogmon.sinks.archive")
    assert r.returncode == 0, r.stderr
    code = ("import sys, fogmon.pipeline, fogmon.sources.open, fogmon.sinks.console, fogmon.sinks.archive\n"
            "print(sorted(m for m in sys.modules if m.startswith('fogmon.cli')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_no_test_module_imports_another():
    """Test modules, validation/ and benchmarks/ share code through tests/helpers only:
    none imports a test module or a conftest, at any level (test modules of the same
    name live in different folders, imported by pytest's importlib mode)."""
    repo = ROOT.parent
    tests = {p.stem for p in (repo / "tests").rglob("test_*.py")} | {"conftest"}
    files = [p for d in ("tests", "validation", "benchmarks") for p in sorted((repo / d).rglob("*.py"))]
    bad = [f"{p.relative_to(repo)}:{line}: imports {m}" for p in files for line, m in _every_import(p, repo / "tests")
           if m.split(".")[0] in tests or m.startswith("tests")]
    assert len(files) > 60 and not bad, "\n".join(bad)
