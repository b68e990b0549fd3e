"""The solver registry: every solver by name, with its options and their defaults.

The command line, the experiment server and the reproduction build solvers here and never
choose an algorithm themselves::

    solver = make_solver("alpha", belief_update="paper", gap=1e-6)
    policy = solver.solve(AssistancePOMDP(model, task))

Options are keyword arguments with defaults; ``None`` means the default.  Options that only
other solvers take are ignored (so that one set of command-line options serves every
solver); an option no solver takes is an error.  A solver's module is loaded when the solver is
first built (through the package's names), so that naming the solvers loads none of scipy.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .. import solvers
from ..policies.base import Policy
from .agnostic import PAPER_HORIZON, TrustAgnosticSolver
from .base import Solver, SolverError
from .defaults import DEFAULT_GRID, DEFAULT_SCHEDULE_GRID
from .scheduling import ScheduleSolver

__all__ = ["SOLVERS", "SolverEntry", "make_solver", "solve_with", "solver_names"]


@dataclass(frozen=True)
class SolverEntry:
    """A registered solver: its name, how to build it, and one line saying what it does."""

    name: str
    build: Callable[..., Solver]
    summary: str

    @property
    def options(self) -> dict[str, Any]:
        """Option -> default."""
        return {k: p.default for k, p in inspect.signature(self.build).parameters.items()}


def _grid(belief_update: str = "bayes", grid: int = DEFAULT_GRID, method: str = "policy-iteration", tol: float = 1e-9) -> Solver:
    return solvers.grid.GridSolver(grid=grid, belief_update=belief_update, method=method, tol=tol)


def _alpha(belief_update: str = "bayes", gap: float = 1e-6) -> Solver:
    return solvers.alpha.AlphaSolver(belief_update=belief_update, tol=gap)


def _certified_grid(belief_update: str = "paper", gap: float = 1e-6) -> Solver:
    return solvers.certified.CertifiedGridSolver(belief_update=belief_update, tol=gap)


def _point(
    belief_update: str = "bayes", gap: float = 1e-3, max_seconds: float = 60.0, max_resolution: int | None = None
) -> Solver:
    return solvers.point.PointSolver(tol=gap, max_seconds=max_seconds, belief_update=belief_update, max_resolution=max_resolution)


def _reachable(belief_update: str = "bayes", gap: float = 1e-3, max_seconds: float = 60.0) -> Solver:
    return solvers.reachable.ReachableSolver(tol=gap, max_seconds=max_seconds, belief_update=belief_update)


def _types(
    belief_update: str = "bayes", gap: float = 1e-3, max_seconds: float = 60.0, max_resolution: int | None = None
) -> Solver:
    return solvers.type_aware.TypeAwareSolver(
        tol=gap, max_seconds=max_seconds, belief_update=belief_update, max_resolution=max_resolution
    )


def _trust_agnostic(horizon: int = PAPER_HORIZON) -> Solver:
    return TrustAgnosticSolver(horizon=horizon)


def _schedule(
    belief_update: str = "bayes",
    representation: str = "grid",
    schedule_grid: int = DEFAULT_SCHEDULE_GRID,
    order: str = "optimal",
    ask_first_hard: bool = False,
) -> Solver:
    return ScheduleSolver(belief_update, representation, schedule_grid, order, ask_first_hard)


SOLVERS: dict[str, SolverEntry] = {
    e.name: e
    for e in (
        SolverEntry("grid", _grid, "belief grid, two trust levels, bayes or paper update (value or policy iteration)"),
        SolverEntry("alpha", _alpha, "certified alpha vectors, two trust levels (bayes; paper via the certified grid)"),
        SolverEntry("certified-grid", _certified_grid, "certified adaptive grid for the eq.-3 update, two trust levels"),
        SolverEntry("point", _point, "point-based bounds at the initial belief, any number of trust levels, bayes update"),
        SolverEntry(
            "reachable", _reachable, "heuristic search over the beliefs reachable from b0, any number of trust levels, bayes"
        ),
        SolverEntry(
            "types",
            _types,
            "point-based bounds capped by the supervisor types' values (type revealed), any number of trust levels, bayes",
        ),
        SolverEntry("trust-agnostic", _trust_agnostic, "the best policy that looks only at the complexity (Section VI-A)"),
        SolverEntry("schedule", _schedule, "trial scheduling: the next item's complexity and the ask, finite horizon"),
    )
}


def solver_names() -> tuple[str, ...]:
    """The registered solvers' names."""
    return tuple(SOLVERS)


def make_solver(name: str, **options: Any) -> Solver:
    """The solver called ``name`` built with ``options`` (``None``: the default)."""
    entry = SOLVERS.get(name)
    if entry is None:
        raise SolverError([f"unknown solver {name!r}; expected one of {list(SOLVERS)}"])
    known = {k for e in SOLVERS.values() for k in e.options}
    unknown = sorted(set(options) - known)
    if unknown:
        raise SolverError([f"unknown solver option {k!r}; options: {sorted(known)}" for k in unknown])
    return entry.build(**{k: v for k, v in options.items() if k in entry.options and v is not None})


def solve_with(name: str, problem: Any, **options: Any) -> Policy:
    """Build the solver called ``name`` and solve ``problem`` with it."""
    return make_solver(name, **options).solve(problem)
