"""The report section on supervisor types (the paper's Remark 1): does a robot that knows the
population has types, and learns which one it works with, rescue the conservative supervisors
the pooled model lost?

:func:`types_section` runs, on the same simulated people (common random numbers: paired
differences), the pooled trust-aware policy (one model fitted to the pooled experiment-1 log);
the type-aware policy of the types fitted to that log (1 to 3, chosen by BIC); the type-aware
policy of the true types (a person's type learned from their interventions and outcomes); the
oracle (each person's own type's policy, the type known in advance); and the trust-agnostic
policy.  It does so at the paper's block length and a longer one, per type and overall, on the
mixture and on its first type alone (where the fitted types should come out as one).  Every
trust-aware policy is solved by :func:`~trustseek.solvers.type_aware.solve_type_aware` (a
one-type mixture for a single model), so that the differences are those of the models, not
of solvers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from ..estimation.fit import fit_trust_model
from ..estimation.mixture import fit_types
from ..estimation.options import FitOptions
from ..model.core import INTERVENE, TrustModel
from ..model.mixture import TypeMixture
from ..model.presets import paper_conservative_mixture, paper_task
from ..model.task import Task
from ..policies.base import Policy
from ..simulation.designs import simulate_design
from ..simulation.engine import simulate
from ..simulation.populations import Supervisors
from ..solvers.agnostic import trust_agnostic_from_data
from ..solvers.type_aware import solve_type_aware
from ..statistics import mean_interval
from ..vocab import PAPER_BLOCK_COUNTS, TRIAL_COLUMNS
from .config import AGNOSTIC

POOLED, TYPE_AWARE, ORACLE = "pooled trust-aware", "type-aware", "oracle (type known)"
FITTED = "type-aware (fitted types)"
POLICIES = (POOLED, FITTED, TYPE_AWARE, ORACLE, AGNOSTIC)
# the paired differences the section reports: (policy, against)
CONTRASTS = (
    (TYPE_AWARE, POOLED),
    (FITTED, POOLED),
    (ORACLE, TYPE_AWARE),
    (ORACLE, POOLED),
    (POOLED, AGNOSTIC),
    (TYPE_AWARE, AGNOSTIC),
)
MAX_TYPES = 3  # the numbers of types compared (by BIC) for the fitted-types policy
# the point solver's finest grid by number of hidden states (type x trust levels): its stop when
# the gap is not reached, instead of a time limit
POINT_RESOLUTION = {2: 4096, 3: 512, 4: 32, 6: 16}


@dataclass
class PopulationRuns:
    """Cumulative reward per block of every participant under each policy (same people, same luck)."""

    name: str
    type_names: tuple[str, ...]
    types: np.ndarray  # (n,) type index of each participant
    counts: tuple[int, ...]  # trials per complexity in the block
    rewards: dict[str, np.ndarray]  # policy -> (n,)
    low_interventions: dict[str, np.ndarray] = field(default_factory=dict)  # policy -> (n,) interventions in low complexity

    def groups(self) -> list[tuple[str, np.ndarray]]:
        """(label, participant mask): each type present, then everyone."""
        out = [(t, self.types == m) for m, t in enumerate(self.type_names) if (self.types == m).any()]
        return [*out, ("all", np.ones(len(self.types), dtype=bool))] if len(out) > 1 else out


@dataclass
class TypesSection:
    """The section's numbers (JSON-ready), the policies and the simulated runs behind the figure."""

    numbers: dict[str, Any]
    policies: dict[str, Any]
    runs: list[PopulationRuns]


def _pooled_fit(mixture: TypeMixture, task: Task, participants: int, seed: int, restarts: int) -> tuple[TrustModel, Any]:
    """The paper's estimate for this population: experiment 1 (paper design) on ``participants``
    people of the mixture, one pooled model fitted to all of it."""
    sup = Supervisors.from_mixture(mixture, participants, rng=seed)
    frame = simulate_design(sup, participants, seed=seed, task=task)
    fit = fit_trust_model(frame[list(TRIAL_COLUMNS)], preset="paper", options=FitOptions(restarts=restarts, seed=seed))
    return fit.model, frame


def _fitted_types(frame: pd.DataFrame, restarts: int, seed: int) -> tuple[TypeMixture, list[dict[str, float]]]:
    """The supervisor types a researcher would fit to the experiment-1 log: 1..MAX_TYPES types,
    the number with the lowest BIC (a one-type choice is the pooled structure's own fit)."""
    rows, fits = [], []
    for m in range(1, MAX_TYPES + 1):
        fit = fit_types(frame[list(TRIAL_COLUMNS)], m, options=FitOptions(restarts=restarts, seed=seed))
        rows.append({"types": m, "loglik": float(fit.loglik), "bic": float(fit.bic)})
        fits.append(fit)
    best = min(range(len(rows)), key=lambda i: rows[i]["bic"])
    return fits[best].mixture(), rows


def _run(
    name: str,
    population: TypeMixture,
    task: Task,
    policies: dict[str, Policy],
    oracle: Sequence[Policy],
    counts: tuple[int, ...],
    participants: int,
    seed: int,
) -> PopulationRuns:
    """Every policy on the same ``participants`` people of ``population`` (one block each, same seed)."""
    sup = Supervisors.from_mixture(population, participants, rng=seed)
    rewards: dict[str, np.ndarray] = {}
    low: dict[str, np.ndarray] = {}
    low_c = task.complexities.index("low") if "low" in task.complexities else 0

    def one(pol: Policy) -> tuple[np.ndarray, np.ndarray]:
        trials = simulate(sup, task, pol, counts=counts, seed=seed, record=True)
        a = trials.arrays or {}
        return trials.reward_matrix()[:, 0], ((a["complexity"] == low_c) & (a["human"] == INTERVENE)).sum(axis=1).astype(float)

    for label, pol in policies.items():
        rewards[label], low[label] = one(pol)
    # the oracle: each type's own policy run on everyone with the same random numbers; each
    # person keeps the run of their own type
    per_type = [one(p) for p in oracle]
    idx = sup.index
    rewards[ORACLE] = np.choose(idx, [r for r, _ in per_type])
    low[ORACLE] = np.choose(idx, [i for _, i in per_type])
    return PopulationRuns(name, population.names, idx.copy(), counts, rewards, low)


def _numbers(runs: PopulationRuns) -> dict[str, Any]:
    out: dict[str, Any] = {"population": runs.name, "counts": list(runs.counts), "trials": int(sum(runs.counts))}
    groups = []
    for label, mask in runs.groups():
        g: dict[str, Any] = {"group": label, "participants": int(mask.sum()), "reward": {}, "low_interventions": {}}
        for p in POLICIES:
            if p in runs.rewards:
                g["reward"][p] = mean_interval(runs.rewards[p][mask])
                g["low_interventions"][p] = float(runs.low_interventions[p][mask].mean())
        g["differences"] = [
            {"policy": a, "against": b, **mean_interval(runs.rewards[a][mask] - runs.rewards[b][mask])}
            for a, b in CONTRASTS
            if a in runs.rewards and b in runs.rewards
        ]
        groups.append(g)
    out["groups"] = groups
    return out


def _verdicts(numbers: list[dict[str, Any]], conservative: str) -> list[str]:
    """Plain sentences on the section's questions, from the paired intervals."""

    def diff(block: dict[str, Any], group: str, a: str, b: str) -> dict[str, Any] | None:
        pairs = (d for g in block["groups"] if g["group"] == group for d in g["differences"])
        return next((d for d in pairs if (d["policy"], d["against"]) == (a, b)), None)

    def say(d: dict[str, Any]) -> str:
        return f"{d['mean']:+.2f} [{d['low']:+.2f}, {d['high']:+.2f}]"

    out = []
    for block in numbers:
        where = f"{block['population']}, {block['trials']}-trial blocks"
        group = "all" if any(g["group"] == "all" for g in block["groups"]) else block["groups"][0]["group"]
        for policy, label in ((TYPE_AWARE, "the type-aware policy (the true types)"), (FITTED, "the policy of the fitted types")):
            whole = diff(block, group, policy, POOLED)
            if whole is None:
                continue
            verdict = "gains" if whole["low"] > 0 else "loses" if whole["high"] < 0 else "neither gains nor loses measurably"
            out.append(f"{where}: {label} {verdict} against the pooled one per block, {say(whole)} (paired 95 % CI).")
        cons = diff(block, conservative, TYPE_AWARE, POOLED)
        orc = diff(block, conservative, ORACLE, TYPE_AWARE)
        best = diff(block, conservative, ORACLE, POOLED)
        if cons is not None and orc is not None and best is not None:
            if best["low"] <= 0 <= best["high"]:
                room = f"no policy does measurably better for them than the pooled one (oracle − pooled {say(best)})"
            else:
                room = f"their own type's policy would change their reward by {say(best)} over the pooled one"
            out.append(
                f"{where}: for the {conservative} supervisors, type-aware − pooled is {say(cons)} and {room}; knowing the "
                f"type in advance would add {say(orc)} to the type-aware policy."
            )
    return out


@dataclass(frozen=True)
class _PopulationPolicies:
    """A population's policies planned from its experiment-1 log: the pooled model's, the
    trust-agnostic one and the fitted types' (with the fits BIC chose among)."""

    model: TrustModel
    pooled: Policy
    agnostic: Policy
    fitted_types: TypeMixture
    fitted_rows: list[dict[str, Any]]
    fitted: Policy

    @classmethod
    def planned(
        cls, population: TypeMixture, task: Task, plan: Callable[[Any], Policy], participants: int, seed: int, restarts: int
    ) -> _PopulationPolicies:
        model, frame = _pooled_fit(population, task, participants, seed, restarts)
        pooled = plan(model)
        agnostic = trust_agnostic_from_data(frame, task)
        fitted_types, rows = _fitted_types(frame, restarts, seed)
        return cls(model, pooled, agnostic, fitted_types, rows, plan(fitted_types))

    def with_aware(self, type_aware: Policy) -> dict[str, Policy]:
        """The policies a run of this population compares, with the type-aware one."""
        return {POOLED: self.pooled, FITTED: self.fitted, TYPE_AWARE: type_aware, AGNOSTIC: self.agnostic}

    def chosen(self) -> dict[str, Any]:
        """The number of types BIC chose and the fits compared."""
        return {"chosen": self.fitted_types.n_types, "fits": self.fitted_rows}


def types_section(
    mixture: TypeMixture | None = None,
    task: Task | None = None,
    participants: int = 2000,
    block_counts: Sequence[tuple[int, ...]] = (PAPER_BLOCK_COUNTS, (68, 68)),
    fit_participants: int = 200,
    restarts: int = 4,
    seed: int = 0,
    gap: float = 0.03,
    max_seconds: float = 600.0,
    progress: Callable[[str], None] | None = None,
) -> TypesSection:
    """Every number of the section: per population (the mixture, then its first type alone), per
    block length, per type and overall, the mean cumulative reward per block of each policy with
    95 % intervals, the paired differences, and interventions in low complexity.

    Every trust-aware policy is solved to a certified ``gap`` at its initial belief, or to the
    point solver's finest grid of :data:`POINT_RESOLUTION` (then the gap reached is recorded; a
    fixed grid, not a clock, so that the same seed gives the same numbers): 0.03 is 0.03 % of
    the value of a discounted block here, below any difference the simulated rewards can show.
    ``max_seconds`` is only a safety net."""
    mixture = mixture or paper_conservative_mixture()
    task = task or paper_task()
    tick = progress or (lambda _s: None)
    seeds = np.random.SeedSequence(seed).generate_state(4)
    task_levels = mixture.models[0].n_trust

    def plan(m: TypeMixture | TrustModel) -> Policy:  # every trust-aware policy, by the same solver
        levels = (m.n_types if isinstance(m, TypeMixture) else 1) * task_levels
        return solve_type_aware(m, task, gap=gap, max_seconds=max_seconds, max_resolution=POINT_RESOLUTION.get(levels, 16))

    main = _PopulationPolicies.planned(mixture, task, plan, fit_participants, int(seeds[0]), restarts)
    tick("pooled fit")
    type_aware = plan(mixture)
    oracle = [plan(m) for m in mixture.models]
    tick("policies")
    # the one-type population: the first type alone; its pooled policy is fitted from its own data
    alone = TypeMixture.single(mixture.models[0], mixture.names[0])
    one = _PopulationPolicies.planned(alone, task, plan, fit_participants, int(seeds[1]), restarts)
    tick("one-type policies")
    runs: list[PopulationRuns] = []
    for j, counts in enumerate(block_counts):
        counts = tuple(int(c) for c in counts)
        both = " + ".join(mixture.names)
        runs.append(_run(both, mixture, task, main.with_aware(type_aware), oracle, counts, participants, int(seeds[2]) + j))
        name = f"{mixture.names[0]} alone"
        runs.append(_run(name, alone, task, one.with_aware(type_aware), oracle[:1], counts, participants, int(seeds[3]) + j))
        tick(f"blocks of {sum(counts)} trials")
    numbers = [_numbers(r) for r in runs]
    conservative = mixture.names[-1]
    info = getattr(type_aware, "info", {}) or {}
    out: dict[str, Any] = {
        "types": [{"name": n, "weight": float(w)} for n, w in zip(mixture.names, mixture.weights, strict=True)],
        "participants": participants,
        "fit_participants": fit_participants,
        "seed": seed,
        # what the type-aware solve reached (not its seconds: the same seed gives the same summary)
        "type_aware_solver": {
            k: info[k] for k in ("solver", "certified_gap", "target_gap", "value_bounds_at_initial_belief") if k in info
        },
        # the numbers of types fitted to each population's experiment-1 log, and the one BIC chose
        "fitted_types": {
            " + ".join(mixture.names): main.chosen(),
            f"{mixture.names[0]} alone": one.chosen(),
        },
        "populations": numbers,
        "verdicts": _verdicts(numbers, conservative),
    }
    policies = {
        POOLED: main.pooled,
        FITTED: main.fitted,
        TYPE_AWARE: type_aware,
        AGNOSTIC: main.agnostic,
        "oracle": oracle,
        "pooled model": main.model,
        "fitted types": main.fitted_types,
    }
    return TypesSection(out, policies, runs)
