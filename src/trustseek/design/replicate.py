"""One replicate of a study: simulate experiment 1 → fit → solve → exact evaluation → experiment 2
→ the pre-registered tests.

Everything a replicate draws comes from ``np.random.SeedSequence([sweep seed, design point,
replicate])``, so a replicate's numbers do not depend on where or in which order it runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import TrustseekError
from ..estimation.fit import fit_sequences
from ..estimation.options import FitOptions
from ..estimation.sequences import Sequences
from ..estimation.spec import IOHMMSpec
from ..estimation.trust_iohmm import preset_spec
from ..model.core import TrustModel
from ..model.task import Task
from ..policies import ComplexityPolicy, randomized
from ..reproduction.config import seed_int
from ..reproduction.robustness import solve_policy
from ..simulation import Simulation, crossover, simulate
from ..solvers.agnostic import agnostic_from_intervention_rates, trust_agnostic_from_data
from ..solvers.base import one_blas_thread
from ..statistics import paired_tests
from ..vocab import ACTIONS, AUTONOMOUS, EXPERIENCES, HUMAN_ACTIONS, INTERVENE, LEVELS
from .evaluation import EVALUATION_GRID, evaluate_policy, high_threshold

__all__ = ["Experiment1", "FitSettings", "Study", "replicate_seed", "run_replicate"]


@dataclass(frozen=True)
class Experiment1:
    """A data-collection design: participants x trials (``high`` of them high complexity, the
    rest low, in random order) under the randomized policy that asks with ``ask_low`` /
    ``ask_high``."""

    participants: int
    trials: int
    high: int
    ask_low: float
    ask_high: float

    @property
    def counts(self) -> tuple[int, int]:
        return (self.trials - self.high, self.high)

    def to_dict(self) -> dict[str, Any]:
        return {
            "participants": self.participants,
            "trials": self.trials,
            "counts": list(self.counts),
            "ask_low": self.ask_low,
            "ask_high": self.ask_high,
        }


@dataclass(frozen=True)
class FitSettings:
    """How each replicate fits the IOHMM (the ``paper`` structure) and plans."""

    restarts: int = 2
    tol: float = 1e-8
    max_iter: int = 1000
    belief_update: str = "paper"
    grid: int = 201
    evaluation_grid: int = EVALUATION_GRID


@dataclass(frozen=True)
class Study:
    """What every replicate shares: the true population, the task, the fit settings and
    experiment 2's grid (participants are prefixes of one crossover of ``max(participants_2)``
    participants per block length, so the power curve over participants uses common random
    numbers)."""

    truth: TrustModel
    task: Task
    fit: FitSettings
    participants_2: tuple[int, ...]
    trials_2: tuple[int, ...]  # trials per block, split evenly over the complexities
    counterbalance: bool = True
    alpha: float = 0.05
    optimal_value: float = float("nan")  # V*(b0) under the truth
    optimal_threshold: float = float("nan")
    seed: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


def replicate_seed(seed: int, point: int, replicate: int) -> np.random.SeedSequence:
    """The seed of replicate ``replicate`` of design point ``point`` of a sweep seeded ``seed``."""
    return np.random.SeedSequence([int(seed), int(point), int(replicate)])


def block_counts(trials: int, n_complexity: int) -> tuple[int, ...]:
    """``trials`` per block split as evenly as possible over the complexities (the paper: 17/17)."""
    base, rest = divmod(int(trials), n_complexity)
    return tuple(base + (1 if c < rest else 0) for c in range(n_complexity))


def fit_encoded(seqs: Sequences, spec: IOHMMSpec, settings: FitSettings, seed: int) -> TrustModel:
    """The model a replicate fits to experiment 1's trials, encoded for ``spec``:
    :func:`~trustseek.estimation.fit_trust_model`'s (the ``paper`` preset, one thread), without
    marking the rows no trial informs (neither the plan nor the simulation reads them)."""
    fit = fit_sequences(
        seqs,
        spec,
        options=FitOptions(restarts=settings.restarts, seed=seed, tol=settings.tol, max_iter=settings.max_iter, n_jobs=1),
    )
    return fit.model


def _recorded(sim: Simulation) -> dict[str, np.ndarray]:
    """The recorded trials of experiment 1, as integer arrays."""
    if sim.arrays is None:
        raise TrustseekError(["experiment 1 must record its trials"])
    return sim.arrays


def experiment1_sequences(sim: Simulation) -> tuple[Sequences, IOHMMSpec]:
    """The ``paper`` spec and the encoded trials of a recorded one-block simulation, straight from
    its integer arrays: what :func:`~trustseek.estimation.sequences.encode` makes of
    ``sim.trials()`` with ``preset_spec("paper", frame)``, without the frame of strings (the
    tests check that both are equal)."""
    arr = _recorded(sim)
    n, T = arr["complexity"].shape
    cx = tuple(sim.task.complexities)
    used = np.flatnonzero(np.bincount(arr["complexity"].reshape(-1).astype(np.int64), minlength=len(cx)))
    present = {cx[k] for k in used}
    extra = sorted(present - set(LEVELS))  # preset_spec's complexities for a column of these values
    spec = preset_spec("paper", None, complexities=LEVELS if not extra else [c for c in LEVELS if c in present] + extra)
    lookups = {
        "complexity": (cx, arr["complexity"]),
        "robot_action": (ACTIONS, arr["action"]),
        "experience": (EXPERIENCES, arr["experience"]),
        spec.output: (HUMAN_ACTIONS, arr["human"]),
    }

    def code(col: str) -> np.ndarray:  # (T, n) codes of a column in the spec's categories
        names, values = lookups[col]
        cats = spec.output_categories if col == spec.output else spec.categories[col]
        lookup = np.array([list(cats).index(v) for v in names], dtype=np.int32)
        return np.ascontiguousarray(lookup[values.astype(np.int64)].T)

    def combination(inputs: tuple[str, ...]) -> np.ndarray:
        out = np.zeros((T, n), dtype=np.int32)
        for col in inputs:
            out *= len(spec.categories[col])
            out += code(col)
        return out.astype(np.int16 if np.prod([len(spec.categories[c]) for c in inputs]) < 2**15 else np.int32)

    rows = np.arange(n * T, dtype=np.int32).reshape(n, T).T.copy()
    seqs = Sequences(
        participants=[str(p) for p in sim.participants],
        lengths=np.full(n, T, dtype=np.int64),
        y=code(spec.output).astype(np.int16),
        ue=combination(spec.emission_inputs),
        ut=combination(spec.transition_inputs),
        rows=rows,
        n_rows=n * T,
        base=1,
        trial_of_row=np.tile(np.arange(1, T + 1, dtype=np.int64), n),
    )
    return seqs, spec


def agnostic_of(sim: Simulation) -> ComplexityPolicy:
    """The trust-agnostic policy from experiment 1's trials (as
    :func:`~trustseek.solvers.agnostic.trust_agnostic_from_data` of ``sim.trials()``: P(intervene |
    C, autonomous) estimated by its share), on the simulation's integer arrays."""
    arr = _recorded(sim)
    c = arr["complexity"].reshape(-1)
    auto = arr["action"].reshape(-1) == AUTONOMOUS
    intervene = arr["human"].reshape(-1) == INTERVENE
    p_int = []
    for k in range(sim.task.n_complexity):
        sel = auto & (c == k)
        if not sel.any():
            return trust_agnostic_from_data(sim.trials(), sim.task)  # raises, naming the complexity
        p_int.append(float(np.mean(intervene[sel])))
    return agnostic_from_intervention_rates(sim.task, p_int, source=f"data, {len(c)} trials")


def run_replicate(study: Study, point: int, design: Experiment1, replicate: int) -> dict[str, Any]:
    """One replicate of ``design`` (design point ``point``): regret and threshold error of the
    estimated policy under the truth, and per experiment-2 setting the p-values of both tests."""
    s1, sfit, s2 = replicate_seed(study.seed, point, replicate).spawn(3)
    truth, task, fs = study.truth, study.task, study.fit
    out: dict[str, Any] = {"point": point, "replicate": replicate}
    ask = randomized({task.complexities[0]: design.ask_low, task.complexities[-1]: design.ask_high})
    sim1 = simulate(truth, task, ask, design.participants, counts=design.counts, seed=s1)
    try:
        model = fit_encoded(*experiment1_sequences(sim1), fs, seed_int(sfit))
        aware = solve_policy(model, task, fs.belief_update, fs.grid)
        agnostic = agnostic_of(sim1)
    except TrustseekError as exc:
        out["error"] = "; ".join(exc.lines())
        return out
    value = evaluate_policy(aware, truth, task, grid=fs.evaluation_grid).value
    out["value"] = value
    out["regret"] = study.optimal_value - value
    # what experiment 2 can detect at best: the estimated policy's exact advantage over the
    # trust-agnostic one it is compared with (discounted, under the true model)
    out["advantage"] = value - evaluate_policy(agnostic, truth, task, grid=fs.evaluation_grid).value
    th = high_threshold(aware)
    out["threshold"] = th
    out["threshold_error"] = abs(th - study.optimal_threshold)
    tests: list[dict[str, Any]] = []
    n_max = max(study.participants_2)
    for k, (trials, ss) in enumerate(zip(study.trials_2, s2.spawn(len(study.trials_2)), strict=True)):
        first = None if study.counterbalance else np.zeros(n_max, dtype=np.int64)
        sim = crossover(
            truth,
            task,
            [aware, agnostic],
            n_max,
            counts=block_counts(trials, task.n_complexity),
            first=first,
            seed=ss,
            record=False,
            belief_model=model,
        )
        r = sim.summary_arrays["cumulative_reward"]  # (n, 2): aware, agnostic
        for n in study.participants_2:
            tests.append({"trials_2": k, "participants_2": n, **paired_tests(r[:n, 0], r[:n, 1])})
    out["tests"] = tests
    return out


@one_blas_thread()
def run_chunk(study: Study, items: Sequence[tuple[int, Experiment1, int]]) -> list[dict[str, Any]]:
    """Several replicates in one task (what an executor runs)."""
    return [run_replicate(study, point, design, rep) for point, design, rep in items]
