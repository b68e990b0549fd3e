"""Solvers: turn a problem into a policy, ``solver.solve(problem) -> Policy``.

* :mod:`.base`           -- the ``Solver`` interface and its errors;
* :mod:`.registry`       -- every solver by name with its options (``make_solver``);
* :mod:`.grid`           -- the belief grid (two trust levels, both updates);
* :mod:`.alpha`          -- certified alpha vectors (two trust levels);
* :mod:`.certified_grid` -- the certified adaptive grid for the eq.-3 update;
* :mod:`.point`          -- point-based bounds (any number of trust levels, flat POMDPs too);
* :mod:`.agnostic`       -- the trust-agnostic optimum (Section VI-A);
* :mod:`.type_solver`    -- point-based bounds that use the supervisor types of a product problem;
* :mod:`.type_aware`     -- ``solve_type_aware``: the policy for a person of unknown supervisor type;
* :mod:`.specs`          -- one policy from a short spec (``policy_from_spec``);
* :mod:`.summary`        -- the machine-readable summary of a solved policy.

Inside: :mod:`.numerics` (policy evaluation, Howard's improvement, controller values),
:mod:`.envelopes` and :mod:`.backup` (the exact alpha-vector backup), :mod:`.eq3` (the
eq.-3 belief MDP), :mod:`.certificate` (certified two-level solutions and their thresholds).
"""

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
