"""Trial logs: column mapping, reading (with located errors) and writing."""

from .cells import DataError
from .mapping import CANONICAL, ColumnMapping
from .trials import example_path, read_trials, write_trials

__all__ = ["CANONICAL", "ColumnMapping", "DataError", "example_path", "read_trials", "write_trials"]
