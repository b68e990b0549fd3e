"""The solver registry: every solver by name, with its options and their defaults, and every
policy by a short spec (:func:`policy_from_spec`), solved through it.

The command line, the experiment server and the reproduction build solvers here and never
choose an algorithm themselves: ``make_solver("alpha", belief_update="paper", gap=1e-6).solve(pomdp)``.
Options are keyword arguments with defaults (``None``: the default); options that only other
solvers take are ignored, an option no solver takes is an error.  A solver's module is loaded
when the solver is first built, so that naming the solvers loads none of scipy.

A policy spec (``trustseek simulate --policy``, a study's blocks) is a JSON object::

    {"kind": "trust-aware", "belief_update": "bayes", "grid": 2001}   solved by the grid solver
    {"kind": "trust-agnostic"}                                         Section VI-A, from the model
    {"kind": "randomized", "p_ask": {"low": 0.1, "high": 0.4}}         (default: the paper's design)
    {"kind": "always-ask"} / {"kind": "never-ask"}
    {"kind": "schedule", "counts": {"low": 17, "high": 17}, "window": null}
                                    trial scheduling (options: belief_update, grid, order, ask_first_hard)

or a full policy JSON (with ``format``), taken as it is.  Every problem is reported at once,
each line naming where in the spec it is (``where``).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from .. import solvers
from ..errors import TrustseekError
from ..model.core import TrustModel
from ..model.jsonfile import ModelError
from ..model.task import Task
from ..policies.base import Policy
from ..policies.complexity import ComplexityPolicy, always_ask, never_ask, randomized
from ..policies.kinds import policy_from_dict
from ..policies.scheduling import SCHEDULE
from ..pomdp.problem import AssistancePOMDP
from ..pomdp.scheduling import SchedulingError, SchedulingProblem, schedule_size
from ..vocab import BELIEF_UPDATES, PAPER_ASK_PROBABILITIES, POLICY_SPEC_KINDS
from .agnostic import PAPER_HORIZON, TrustAgnosticSolver
from .base import Solver, SolverError
from .defaults import DEFAULT_GRID, DEFAULT_SCHEDULE_GRID, ORDERS


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
    return solvers.scheduling.ScheduleSolver(belief_update, representation, schedule_grid, order, ask_first_hard)


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


def solve(
    model: TrustModel,
    task: Task,
    belief_update: str = "bayes",
    grid: int = DEFAULT_GRID,
    method: str = "policy-iteration",
    tol: float = 1e-9,
) -> Policy:
    """Solve the assistance POMDP of ``model`` and ``task`` for the trust-aware policy (the grid solver)."""
    return make_solver("grid", belief_update=belief_update, grid=grid, method=method, tol=tol).solve(AssistancePOMDP(model, task))


# --------------------------------------------------------------------------- policies by spec


#: the kinds of a plain policy (``trustseek simulate --policy`` names these)
SPEC_KINDS = POLICY_SPEC_KINDS
SPEC_ENTRIES = ("kind", "belief_update", "grid", "p_ask")
SCHEDULE_ENTRIES = ("kind", "counts", "window", "belief_update", "grid", "order", "ask_first_hard")


class PolicySpecError(TrustseekError, ValueError):
    """A policy spec that does not name a policy; one line per problem."""


def policy_from_spec(
    spec: Any,
    model: TrustModel,
    task: Task,
    where: str = "policy",
    max_grid: int | None = None,
    max_values: int | None = None,
) -> Policy:
    """The policy a spec names, for ``model`` and ``task`` (solving the POMDP for ``trust-aware``
    and the scheduling problem for ``schedule``).

    ``max_grid`` caps the grid of a trust-aware spec and ``max_values`` the size of a schedule
    spec's policy (states x complexities x actions x grid points, bounded before solving): a
    server limits the work a request can ask for."""
    if not isinstance(spec, Mapping):
        raise PolicySpecError([f"{where} must be an object"])
    if "format" in spec:
        pol = policy_from_dict(spec, where)
        if tuple(pol.complexities) != tuple(task.complexities):
            ours, theirs = list(pol.complexities), list(task.complexities)
            raise PolicySpecError([f"{where}: complexities {ours} differ from the task's {theirs}"])
        return pol
    kind = spec.get("kind")
    if kind == SCHEDULE:
        return _schedule_spec(spec, model, task, where, max_values)
    extra = sorted(set(spec) - set(SPEC_ENTRIES))
    if extra:
        raise PolicySpecError([f"{where} has unknown entries {extra} (expected some of {sorted(SPEC_ENTRIES)})"])
    if kind not in SPEC_KINDS:
        kinds = [*SPEC_KINDS, SCHEDULE]
        raise PolicySpecError([f"{where}.kind is {kind!r}, expected one of {kinds} (or give a full policy JSON)"])
    cx = task.complexities
    if kind == "trust-aware":
        return _trust_aware_spec(spec, model, task, where, max_grid)
    if kind == "trust-agnostic":
        return make_solver("trust-agnostic").solve(AssistancePOMDP(model, task))
    if kind == "randomized":
        return _randomized_spec(spec.get("p_ask"), cx, where)
    return always_ask(cx) if kind == "always-ask" else never_ask(cx)


def _trust_aware_spec(spec: Mapping[str, Any], model: TrustModel, task: Task, where: str, max_grid: int | None) -> Policy:
    problems: list[str] = []
    bu, grid = _update_and_grid(spec, where, DEFAULT_GRID, max_grid, problems)
    if problems:
        raise PolicySpecError(problems)
    return _solved(make_solver("grid", belief_update=bu, grid=grid), AssistancePOMDP(model, task), where)


def _update_and_grid(spec: Mapping[str, Any], where: str, default: int, max_grid: int | None, problems: list[str]) -> tuple:
    """A spec's ``belief_update`` and ``grid`` (at most ``max_grid``); what is wrong goes to ``problems``."""
    bu = spec.get("belief_update", "bayes")
    grid = spec.get("grid", default)
    if bu not in BELIEF_UPDATES:
        problems.append(f"{where}.belief_update is {bu!r}, expected {' or '.join(repr(b) for b in BELIEF_UPDATES)}")
    if not isinstance(grid, int) or isinstance(grid, bool) or not 3 <= grid <= (float("inf") if max_grid is None else max_grid):
        expected = f"an integer in [3, {max_grid}]" if max_grid is not None else "an integer of at least 3"
        problems.append(f"{where}.grid is {grid!r}, expected {expected}")
    return bu, grid


def _solved(solver: Solver, problem: Any, where: str) -> Policy:
    """``solver``'s policy for ``problem``, or what keeps it from solving it, each line at ``where``."""
    reasons = solver.unsupported(problem)
    if reasons:
        raise PolicySpecError([f"{where}: {r}" for r in reasons])
    return solver.solve(problem)


def _randomized_spec(p: Any, cx: tuple[str, ...], where: str) -> ComplexityPolicy:
    if p is None:  # the paper's design when the task has its complexities
        return randomized(PAPER_ASK_PROBABILITIES if cx == tuple(PAPER_ASK_PROBABILITIES) else dict.fromkeys(cx, 0.25))
    if not isinstance(p, Mapping) or set(p) != set(cx):
        raise PolicySpecError([f"{where}.p_ask must map each complexity {list(cx)} to a probability, got {p!r}"])
    try:
        return ComplexityPolicy("randomized", cx, [p[c] for c in cx])
    except ModelError as exc:
        raise PolicySpecError([f"{where}: {x}" for x in exc.problems]) from None


def _schedule_spec(spec: Mapping[str, Any], model: TrustModel, task: Task, where: str, max_values: int | None) -> Policy:
    problems = []
    extra = sorted(set(spec) - set(SCHEDULE_ENTRIES))
    if extra:
        problems.append(f"{where} has unknown entries {extra} (expected some of {sorted(SCHEDULE_ENTRIES)})")
    cx = task.complexities
    counts = spec.get("counts")
    if isinstance(counts, Mapping) and set(counts) <= set(cx):
        counts = [counts.get(c, 0) for c in cx]
    if not (
        isinstance(counts, list | tuple)
        and len(counts) == len(cx)
        and all(isinstance(k, int) and not isinstance(k, bool) and k >= 0 for k in counts)
        and sum(counts) >= 1
    ):
        problems.append(
            f"{where}.counts must give a non-negative number of items for each complexity {list(cx)} "
            f"(an object by name or a list), at least one item in all, got {spec.get('counts')!r}"
        )
        counts = None
    window = spec.get("window")
    if window is not None and (not isinstance(window, int) or isinstance(window, bool) or window < 1):
        problems.append(f"{where}.window is {window!r}, expected a positive number of items or null (every item)")
    bu, grid = _update_and_grid(spec, where, DEFAULT_SCHEDULE_GRID, None, problems)
    order = spec.get("order", "optimal")
    if order not in ORDERS:
        problems.append(f"{where}.order is {order!r}, expected one of {list(ORDERS)}")
    first = spec.get("ask_first_hard", False)
    if not isinstance(first, bool):
        problems.append(f"{where}.ask_first_hard is {first!r}, expected true or false")
    if problems:
        raise PolicySpecError(problems)
    assert counts is not None
    size = schedule_size(tuple(counts), window, grid)
    if max_values is not None and size > max_values:
        raise PolicySpecError(
            [
                f"{where}: a schedule policy for counts {list(counts)}, window {window} and grid {grid} could hold "
                f"{size} values, more than the {max_values} allowed here: use fewer items, a smaller window or grid"
            ]
        )
    try:
        problem = SchedulingProblem(AssistancePOMDP(model, task), tuple(counts), window)
    except SchedulingError as exc:
        raise PolicySpecError([f"{where}: {x}" for x in exc.problems]) from None
    return _solved(make_solver(SCHEDULE, belief_update=bu, schedule_grid=grid, order=order, ask_first_hard=first), problem, where)
