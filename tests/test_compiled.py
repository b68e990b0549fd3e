"""The compiled code is built with the package: every Cython source is an extension of setup.py,
installed compiled, with a stub for the type checker; nothing in the package uses numba."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import trustseek

PACKAGE = Path(trustseek.__file__).resolve().parent
ROOT = PACKAGE.parent.parent


def _extensions() -> dict[str, str]:
    """setup.py's extensions: module name -> source path."""
    tree = ast.parse((ROOT / "setup.py").read_text())
    out = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and ast.unparse(node.func) == "Extension":
            name, sources = node.args[0], node.args[1]
            assert isinstance(name, ast.Constant) and isinstance(sources, ast.List)
            out[name.value] = sources.elts[0].value  # type: ignore[attr-defined]
    return out


def test_every_cython_source_is_an_extension_built_with_the_package_and_stubbed():
    sources = {p.relative_to(ROOT).as_posix() for p in PACKAGE.rglob("*.pyx")}
    extensions = _extensions()
    assert sorted(extensions.values()) == sorted(sources)
    for name, source in extensions.items():
        assert name == source.removeprefix("src/").removesuffix(".pyx").replace("/", ".")
        assert (ROOT / source).with_suffix(".pyi").exists(), f"{source} has no stub"
        module = importlib.import_module(name)
        assert Path(module.__file__ or "").suffix == ".so", f"{name} is not installed compiled"


def test_nothing_in_the_package_imports_numba():
    for path in [*PACKAGE.rglob("*.py"), *PACKAGE.rglob("*.pyx"), *PACKAGE.rglob("*.pxd")]:
        assert "numba" not in path.read_text(), path


def test_every_installed_extension_is_built_from_its_current_source():
    """An edited .pyx or .pxd is built again by ``bash scripts/setup.sh`` (``make test`` runs it);
    a test run on an extension older than its sources would test the old code."""
    shared = [p.stat().st_mtime for p in PACKAGE.rglob("*.pxd")]
    for name, source in _extensions().items():
        built = Path(importlib.import_module(name).__file__ or "").stat().st_mtime
        newest = max([(ROOT / source).stat().st_mtime, *shared])
        assert built >= newest, f"{name} is older than its sources: run bash scripts/setup.sh"
