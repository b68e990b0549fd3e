"""The ``Solver`` interface: ``solver.solve(problem) -> Policy`` (as POMDPs.jl's ``solve``).

Every solver is configured when it is built (its options), says up front which problems it
handles (``unsupported(problem)`` lists the reasons it cannot, each naming an alternative)
and refuses the rest with :class:`UnsupportedProblem` before doing any work.
"""

from __future__ import annotations

import functools
import math
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, ClassVar

from threadpoolctl import ThreadpoolController

from ..errors import TrustseekError
from ..policies.base import Policy
from ..pomdp.flat import FlatPOMDP
from ..pomdp.problem import AssistancePOMDP
from ..vocab import check_belief_update


class SolverError(TrustseekError, ValueError):
    """A solver cannot be built or run as asked (an unknown solver or option, a bad option value)."""


class UnsupportedProblem(SolverError):
    """A solver was given a problem it does not handle; each line names an alternative."""


class Solver:
    """Turns a problem into a policy: ``solve(problem)``.  Holds the checks shared by the solvers
    (the problem type, the number of trust levels, the belief update); subclasses set what they
    handle and what to use instead."""

    name = ""
    trust_levels: int | None = None  # the number of trust levels handled (None: any)
    belief_updates: tuple[str, ...] = ("bayes", "paper")
    belief_update: str | None = None
    tol: float
    max_seconds: float
    #: what to use for a model with another number of trust levels / another belief update /
    #: a problem that is not an assistance POMDP (default: the point solver, which takes any
    #: number of trust levels and flat POMDPs)
    instead: ClassVar[dict[str, str]] = {}
    flat: ClassVar[bool] = False  # solves flat POMDPs (files) too, with a discount below 1
    discounted: ClassVar[bool] = False  # needs a discount below 1 (its bounds rest on the contraction)

    def solve(self, problem: Any) -> Policy:
        """The solver's policy for ``problem`` (raises :class:`UnsupportedProblem` first)."""
        raise NotImplementedError

    def unsupported(self, problem: Any) -> list[str]:
        """Why this solver cannot solve ``problem`` (empty when it can); each reason names an
        alternative."""
        below = f"the {self.name} solver needs a discount below 1, got {getattr(problem, 'discount', None)}"
        if self.flat and isinstance(problem, FlatPOMDP):
            return [] if problem.discount < 1.0 else [below]
        reasons = []
        if not isinstance(problem, AssistancePOMDP):
            reasons.append(
                f"the {self.name} solver needs an assistance POMDP (a trust model and a task), got a "
                f"{type(problem).__name__}: {self.instead.get('problem', 'use the point solver')}"
            )
            return reasons
        if self.trust_levels is not None and problem.n_trust != self.trust_levels:
            reasons.append(
                f"the {self.name} solver needs {_count(self.trust_levels)} trust levels; this model has "
                f"{problem.n_trust}: {self.instead.get('trust_levels', 'use the point solver')}"
            )
        if self.belief_update is not None and self.belief_update not in self.belief_updates:
            default = f"the {self.name} solver does not handle the {self.belief_update!r} update"
            reasons.append(self.instead.get("belief_update", default))
        if self.discounted and not reasons and not problem.discount < 1.0:
            reasons.append(f"{below}: use the grid solver")
        return reasons

    def _targets(self, belief_update: str, tol: float, max_seconds: float | None = None) -> None:
        """Set the belief update (checked), the target gap ``tol`` (a finite number > 0) and, for
        an anytime solver, its time limit ``max_seconds`` (> 0)."""
        if not (tol > 0 and math.isfinite(tol)):
            raise SolverError([f"the target gap must be a finite number > 0, got {tol}"])
        if max_seconds is not None and not max_seconds > 0:
            raise SolverError([f"the time limit must be positive, got {max_seconds}"])
        self.belief_update = check_belief_update(belief_update)
        self.tol = float(tol)
        if max_seconds is not None:
            self.max_seconds = float(max_seconds)

    def check(self, problem: Any) -> None:
        """Raise :class:`UnsupportedProblem` with every reason the problem is not handled."""
        reasons = self.unsupported(problem)
        if reasons:
            raise UnsupportedProblem(reasons)


def bayes_only(name: str) -> dict[str, str]:
    """The ``instead`` of a solver that bounds the value of the Bayes filter only."""
    return {
        "belief_update": f"the {name} solver bounds the value of the Bayes filter (belief update 'bayes'); "
        "for the eq.-3 update use the alpha solver (two trust levels) or the grid solver",
    }


def _count(n: int) -> str:
    return {1: "one", 2: "two", 3: "three"}.get(n, str(n))


_blas_lock = threading.Lock()
_blas_limiters: list[tuple[ThreadpoolController, Any]] = []  # the limits in force while inside: one per controller entered with
_blas_depth = [0]


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS (OpenBLAS, MKL) on one thread: ``with one_blas_thread():`` runs a block so, and
    ``@one_blas_thread()`` a function.  A threaded BLAS splits products and sums differently with
    the number of cores, so their last bits differ and a solver may pick another vector at a near
    tie (the type-aware policy of the reproduction's fitted types moved its lower bound by 1.4e-4
    between one and two threads); the solvers' thin products lose little on one thread, and
    L-BFGS-B's tiny BLAS calls gain two orders of magnitude on a busy machine.

    Reentrant and shared by threads: the limit is set by the first to enter and lifted by the
    last to leave (a thread leaving does not lift it under another still inside)."""
    controller = _blas_controller("scipy.linalg" in sys.modules)
    with _blas_lock:
        if not any(c is controller for c, _ in _blas_limiters):  # first entry, or a BLAS loaded since
            _blas_limiters.append((controller, controller.limit(limits=1, user_api="blas")))
        _blas_depth[0] += 1
    try:
        yield
    finally:
        with _blas_lock:
            _blas_depth[0] -= 1
            if _blas_depth[0] == 0:
                for _, limiter in reversed(_blas_limiters):
                    limiter.restore_original_limits()
                _blas_limiters.clear()


@functools.cache
def _blas_controller(scipy_loaded: bool) -> ThreadpoolController:
    """The thread pools of the BLAS libraries loaded, found once for numpy's alone and once more
    when scipy's is loaded too (the solvers of the paper's small problems never load scipy):
    looking them up again on every call (``threadpool_limits``) cost 0.8 ms a solve, against
    0.01 ms through the one controller."""
    return ThreadpoolController()
