"""The public names of :mod:`trustseek.solvers`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import (
    agnostic,
    alpha,
    backup,
    base,
    certificate,
    certified_grid,
    defaults,
    envelopes,
    eq3,
    grid,
    numerics,
    point,
    reachable,
    registry,
    schedule,
    sensitivity,
    specs,
    summary,
    type_aware,
    type_solver,
)
from .agnostic import TrustAgnosticSolver, trust_agnostic, trust_agnostic_from_data
from .alpha import AlphaSolver
from .base import Solver, SolverError, UnsupportedProblem
from .certified_grid import CertifiedGridSolver
from .grid import GridSolver, solve
from .point import PointSolver
from .registry import SOLVERS, make_solver, solve_with, solver_names
from .specs import PolicySpecError, policy_from_spec
from .summary import summarize
from .type_aware import solve_type_aware
from .type_solver import TypeAwareSolver

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
