"""Solvers: turn an assistance POMDP into a policy."""

from .grid import GridSolver, solve

__all__ = ["GridSolver", "solve"]
