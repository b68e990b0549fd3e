"""The public names of :mod:`trustseek.reproduction`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import comparison, config, coverage, pipeline, scheduling, supervisor_types
from .config import AGNOSTIC, AWARE, PAPER, ReproduceConfig
from .pipeline import Reproduction, reproduce, write_summary

__all__ = ["AGNOSTIC", "AWARE", "PAPER", "ReproduceConfig", "Reproduction", "reproduce", "write_summary"]
