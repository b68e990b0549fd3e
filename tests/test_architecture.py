"""The layering of docs/architecture.md, checked: the import-linter contracts in pyproject.toml
(layers, no cycles, no imports of the package root) hold for the library's import graph."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import grimp

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold():
    """Layers, acyclicity and the ban on importing the package root (``lint-imports``, in its own
    process: its logging set-up would otherwise disable the loggers of the tests that follow)."""
    exe = Path(sys.executable).with_name("lint-imports")
    proc = subprocess.run(
        [str(exe), "--config", str(ROOT / "pyproject.toml"), "--no-cache"], cwd=ROOT, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert ", 0 broken." in proc.stdout


def test_the_import_graph_sees_imports_inside_functions(tmp_path, monkeypatch):
    """A deferred (function-level) import is still an import: the contracts see it."""
    pkg = tmp_path / "layered"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "high.py").write_text("from . import low\n")
    (pkg / "low.py").write_text(
        textwrap.dedent(
            """
            def upward():
                from . import high

                return high
            """
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    graph = grimp.build_graph("layered", cache_dir=None)
    assert graph.direct_import_exists(importer="layered.low", imported="layered.high")
    assert graph.find_shortest_chain(importer="layered.low", imported="layered.high") is not None


def test_solvers_are_built_through_the_registry_outside_the_solvers():
    """Outside ``solvers/`` a solver is made by ``make_solver`` (its options checked once), never by
    its class."""
    import ast

    built = []
    for path in sorted((ROOT / "src" / "trustseek").rglob("*.py")):
        if "solvers" in path.relative_to(ROOT / "src" / "trustseek").parts:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                name = node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", "")
                if name.endswith("Solver"):
                    built.append(f"{path.relative_to(ROOT)}:{node.lineno} {name}")
    assert not built, built


def test_test_modules_have_names_of_their_own():
    """pytest imports a test module by its file name (``rootdir``-relative, no packages), and the
    browser tests import helpers from each other by that name: two test files of one name in
    different folders would break the collection of the other (a ``tests/testing/test_browser.py``
    once shadowed ``tests/web/test_browser.py``)."""
    names: dict[str, list[str]] = {}
    for path in sorted((ROOT / "tests").rglob("*.py")):
        if path.name not in ("__init__.py", "conftest.py"):
            names.setdefault(path.name, []).append(str(path.relative_to(ROOT)))
    assert {n: p for n, p in names.items() if len(p) > 1} == {}


def test_modules_and_functions_stay_small():
    """A module of at most 600 lines, a function of at most 100, and at most 10 parameters outside
    the command line's commands (Typer's options are parameters there): a newcomer reads a module at
    a sitting.  data/sources.py once grew to 612 lines unseen, measured only by hand."""
    import ast

    big, long, wide = [], [], []
    for path in sorted((ROOT / "src" / "trustseek").rglob("*.py")):
        text = path.read_text()
        name = str(path.relative_to(ROOT))
        if text.count("\n") > 600:
            big.append(f"{name}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > 100:
                    long.append(f"{name}:{node.lineno} {node.name}: {lines} lines")
                a = node.args
                count = (
                    len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) - (a.args[:1] != [] and a.args[0].arg in ("self", "cls"))
                )
                if count > 10 and "/cli/" not in name:
                    wide.append(f"{name}:{node.lineno} {node.name}: {count} parameters")
    assert (big, long, wide) == ([], [], [])
