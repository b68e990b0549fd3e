"""The trust-agnostic optimum (Section VI-A): the best policy that looks only at the complexity,
with P(intervene | C, autonomous) from a trust model (averaged over the trust distribution that a
data-collection design produces) or from logged trials."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..model.core import TrustModel
from ..model.task import Task
from ..policies.complexity import ComplexityPolicy, randomized
from ..pomdp.problem import AssistancePOMDP
from ..vocab import AUTONOMOUS, INTERVENE, PAPER_ASK_PROBABILITIES, PAPER_DATA_COUNTS
from .base import Solver, SolverError, one_blas_thread

#: trials per participant of the paper's data collection (41 low + 30 high)
PAPER_HORIZON = sum(PAPER_DATA_COUNTS)


def agnostic_from_intervention_rates(task: Task, p_intervene: Sequence[float], source: str = "") -> ComplexityPolicy:
    """Section VI-A: per complexity, compare the expected one-trial reward of acting
    autonomously, P(rely|C)·(p_suc R_success + (1-p_suc) R_failure) + P(intervene|C) R_intervene,
    with that of asking, and pick the larger (autonomous on ties)."""
    p_int = np.asarray(p_intervene, dtype=float)
    rw = task.rewards
    s = task.success
    r_auto = (1 - p_int) * (s * rw.autonomous_success + (1 - s) * rw.autonomous_failure) + p_int * rw.intervene
    r_ask = np.full_like(r_auto, rw.ask)
    p_ask = (r_ask > r_auto).astype(float)
    info = {
        "p_intervene": {cn: float(p) for cn, p in zip(task.complexities, p_int, strict=True)},
        "expected_reward": {
            cn: {"autonomous": float(ra), "ask": float(rk)} for cn, ra, rk in zip(task.complexities, r_auto, r_ask, strict=True)
        },
        "source": source,
    }
    return ComplexityPolicy("trust-agnostic", task.complexities, p_ask, info)


def trust_occupancy(model: TrustModel, task: Task, data_policy: ComplexityPolicy, horizon: int) -> np.ndarray:
    """Average over trials 1..horizon of the trust marginal P(T_t) when ``data_policy`` runs
    (actions depend on complexity only, so the trust marginal is a Markov chain)."""
    pomdp = AssistancePOMDP(model, task)
    k = pomdp.kernel.sum(axis=(3, 4))  # [c, a, t, u]
    pa = np.stack([1 - data_policy.p_ask, data_policy.p_ask], axis=1)  # [c, a]
    M = np.einsum("c,ca,catu->tu", task.complexity_probs, pa, k)
    p = np.array(model.initial, dtype=float)
    acc = np.zeros_like(p)
    for _ in range(horizon):
        acc += p
        p = p @ M
    return acc / horizon


def trust_agnostic(
    model: TrustModel,
    task: Task,
    data_policy: ComplexityPolicy | None = None,
    horizon: int = PAPER_HORIZON,
) -> ComplexityPolicy:
    """The optimal trust-agnostic policy with P(intervene | C, autonomous) taken from ``model``,
    averaged over the trust distribution that the data-collection design produces (by default
    the paper's: randomized 0.10/0.40 policy, 71 trials)."""
    # by default Section V's design (0.25 for a complexity the paper does not name)
    data_policy = data_policy or randomized({c: PAPER_ASK_PROBABILITIES.get(c, 0.25) for c in task.complexities})
    occ = trust_occupancy(model, task, data_policy, horizon)
    p_int = np.einsum("t,ct->c", occ, model.emission[:, AUTONOMOUS, :, INTERVENE])
    return agnostic_from_intervention_rates(
        task, p_int, source=f"model, trust averaged over {horizon} trials of the {data_policy.describe()} policy"
    )


def trust_agnostic_from_data(trials: Any, task: Task) -> ComplexityPolicy:
    """The optimal trust-agnostic policy with P(intervene | C, autonomous) estimated from logged
    trials (a DataFrame with columns ``complexity``, ``robot_action`` and ``human_action``)."""
    p_int = []
    for cn in task.complexities:
        rows = trials[(trials["complexity"] == cn) & (trials["robot_action"] == "autonomous") & trials["human_action"].notna()]
        if len(rows) == 0:
            raise SolverError([f"no autonomous trials with a recorded human action in complexity {cn!r}"])
        p_int.append(float((rows["human_action"] == "intervene").mean()))
    return agnostic_from_intervention_rates(task, p_int, source=f"data, {len(trials)} trials")


class TrustAgnosticSolver(Solver):
    """The optimal trust-agnostic policy of a model and task (:func:`trust_agnostic`) as a solver:
    any number of trust levels; the policy ignores the belief."""

    name = "trust-agnostic"

    def __init__(self, horizon: int = PAPER_HORIZON, data_policy: ComplexityPolicy | None = None):
        if int(horizon) != horizon or horizon < 1:
            raise SolverError([f"the horizon must be a positive number of trials, got {horizon!r}"])
        self.horizon = int(horizon)
        self.data_policy = data_policy

    @one_blas_thread()
    def solve(self, pomdp: AssistancePOMDP) -> ComplexityPolicy:
        """The trust-agnostic policy; ``info`` says where P(intervene | C) came from."""
        self.check(pomdp)
        return trust_agnostic(pomdp.model, pomdp.task, self.data_policy, self.horizon)
