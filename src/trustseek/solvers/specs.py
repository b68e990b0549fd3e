"""One policy from a short spec: what ``trustseek simulate --policy`` and a study's blocks name.

A spec is a JSON object::

    {"kind": "trust-aware", "belief_update": "bayes", "grid": 2001}   solved by the grid solver
    {"kind": "trust-agnostic"}                                         Section VI-A, from the model
    {"kind": "randomized", "p_ask": {"low": 0.1, "high": 0.4}}         (default: the paper's design)
    {"kind": "always-ask"} / {"kind": "never-ask"}

or a full policy JSON (with ``format``), taken as it is.  Every problem is reported at once,
each line naming where in the spec it is (``where``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..errors import TrustseekError
from ..model.core import ModelError, Task, TrustModel
from ..policies.base import Policy
from ..policies.complexity import ComplexityPolicy, always_ask, never_ask, randomized
from ..policies.kinds import policy_from_dict
from ..pomdp.problem import AssistancePOMDP
from ..vocab import BELIEF_UPDATES, PAPER_ASK_PROBABILITIES, POLICY_SPEC_KINDS
from .grid import DEFAULT_GRID
from .registry import make_solver

__all__ = ["SPEC_KINDS", "PolicySpecError", "policy_from_spec"]

SPEC_KINDS = POLICY_SPEC_KINDS
SPEC_ENTRIES = ("kind", "belief_update", "grid", "p_ask")


class PolicySpecError(TrustseekError, ValueError):
    """A policy spec that does not name a policy; one line per problem."""


def policy_from_spec(spec: Any, model: TrustModel, task: Task, where: str = "policy", max_grid: int | None = None) -> Policy:
    """The policy a spec names, for ``model`` and ``task`` (solving the POMDP for ``trust-aware``).

    ``max_grid`` caps the grid of a trust-aware spec (a server limits the work a request can
    ask for)."""
    if not isinstance(spec, Mapping):
        raise PolicySpecError([f"{where} must be an object"])
    if "format" in spec:
        pol = policy_from_dict(spec, where)
        if tuple(pol.complexities) != tuple(task.complexities):
            ours, theirs = list(pol.complexities), list(task.complexities)
            raise PolicySpecError([f"{where}: complexities {ours} differ from the task's {theirs}"])
        return pol
    extra = sorted(set(spec) - set(SPEC_ENTRIES))
    if extra:
        raise PolicySpecError([f"{where} has unknown entries {extra} (expected some of {sorted(SPEC_ENTRIES)})"])
    kind = spec.get("kind")
    if kind not in SPEC_KINDS:
        raise PolicySpecError([f"{where}.kind is {kind!r}, expected one of {list(SPEC_KINDS)} (or give a full policy JSON)"])
    cx = task.complexities
    if kind == "trust-aware":
        return _trust_aware(spec, model, task, where, max_grid)
    if kind == "trust-agnostic":
        return make_solver("trust-agnostic").solve(AssistancePOMDP(model, task))
    if kind == "randomized":
        return _randomized(spec.get("p_ask"), cx, where)
    return always_ask(cx) if kind == "always-ask" else never_ask(cx)


def _trust_aware(spec: Mapping[str, Any], model: TrustModel, task: Task, where: str, max_grid: int | None) -> Policy:
    bu = spec.get("belief_update", "bayes")
    grid = spec.get("grid", DEFAULT_GRID)
    problems = []
    if bu not in BELIEF_UPDATES:
        problems.append(f"{where}.belief_update is {bu!r}, expected {' or '.join(repr(b) for b in BELIEF_UPDATES)}")
    top = max_grid if max_grid is not None else float("inf")
    if not isinstance(grid, int) or isinstance(grid, bool) or not 3 <= grid <= top:
        expected = f"an integer in [3, {max_grid}]" if max_grid is not None else "an integer of at least 3"
        problems.append(f"{where}.grid is {grid!r}, expected {expected}")
    if problems:
        raise PolicySpecError(problems)
    pomdp = AssistancePOMDP(model, task)
    solver = make_solver("grid", belief_update=bu, grid=grid)
    reasons = solver.unsupported(pomdp)
    if reasons:
        raise PolicySpecError([f"{where}: {r}" for r in reasons])
    return solver.solve(pomdp)


def _randomized(p: Any, cx: tuple[str, ...], where: str) -> ComplexityPolicy:
    if p is None:  # the paper's design when the task has its complexities
        return randomized(PAPER_ASK_PROBABILITIES if cx == tuple(PAPER_ASK_PROBABILITIES) else dict.fromkeys(cx, 0.25))
    if not isinstance(p, Mapping) or set(p) != set(cx):
        raise PolicySpecError([f"{where}.p_ask must map each complexity {list(cx)} to a probability, got {p!r}"])
    try:
        return ComplexityPolicy("randomized", cx, [p[c] for c in cx])
    except ModelError as exc:
        raise PolicySpecError([f"{where}: {x}" for x in exc.problems]) from None
