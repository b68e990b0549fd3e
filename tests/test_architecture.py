"""The layering of docs/architecture.md, checked: the import-linter contracts in pyproject.toml
(layers, no cycles, no imports of the package root) hold for the library's import graph."""

from __future__ import annotations

import logging
import textwrap
from pathlib import Path

import grimp
import importlinter.cli as importlinter_cli

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold():
    """Layers, acyclicity and the ban on importing the package root (``lint-imports``)."""
    loggers = [lg for lg in logging.root.manager.loggerDict.values() if isinstance(lg, logging.Logger) and not lg.disabled]
    try:
        assert importlinter_cli.lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True) == 0
    finally:  # its logging set-up disables every existing logger, which later tests' caplog needs
        for lg in loggers:
            lg.disabled = False


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
