"""The public names of :mod:`trustseek.solvers`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import (
    agnostic,
    alpha,
    base,
    certified,
    defaults,
    grid,
    numerics,
    point,
    reachable,
    registry,
    scheduling,
    sensitivity,
    summary,
    type_aware,
    type_bounds,
    upper_bounds,
)
from .agnostic import TrustAgnosticSolver, trust_agnostic, trust_agnostic_from_data
from .alpha import AlphaSolver
from .base import Solver, SolverError, UnsupportedProblem
from .certified import CertifiedGridSolver
from .grid import GridSolver
from .point import PointSolver
from .registry import SOLVERS, PolicySpecError, make_solver, policy_from_spec, solve, solve_with, solver_names
from .summary import summarize
from .type_aware import TypeAwareSolver, solve_type_aware

__all__ = [
    "SOLVERS",
    "AlphaSolver",
    "CertifiedGridSolver",
    "GridSolver",
    "PointSolver",
    "PolicySpecError",
    "Solver",
    "SolverError",
    "TrustAgnosticSolver",
    "TypeAwareSolver",
    "UnsupportedProblem",
    "make_solver",
    "policy_from_spec",
    "solve",
    "solve_type_aware",
    "solve_with",
    "solver_names",
    "summarize",
    "trust_agnostic",
    "trust_agnostic_from_data",
]
