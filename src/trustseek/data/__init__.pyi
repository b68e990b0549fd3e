"""The public names of :mod:`trustseek.data`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import cells, folders, layouts, levels, mapping, order, sources, statfiles, suffixes, trials, workbooks
from .cells import DataError
from .mapping import CANONICAL, ColumnMapping
from .trials import example_path, read_trials, write_trials

__all__ = ["CANONICAL", "ColumnMapping", "DataError", "example_path", "read_trials", "write_trials"]
