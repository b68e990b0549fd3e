"""The public names of :mod:`trustseek.interop`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import files
from .files import PomdpFileError, export_assistance, read_pomdp, write_pomdp, write_pomdpx

__all__ = ["PomdpFileError", "export_assistance", "read_pomdp", "write_pomdp", "write_pomdpx"]
