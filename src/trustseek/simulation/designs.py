"""Experiment designs on simulated supervisors.

:func:`simulate_design` is the paper's data collection (Section V): trial logs under the
randomized policy.  :func:`crossover` is its evaluation (Section VI-B): every participant
meets every policy, one block each, in a counterbalanced order.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from ..model.core import TrustModel
from ..model.presets import paper_task
from ..model.task import Task
from ..policies import Policy, randomized
from ..seeds import seed_sequence
from ..vocab import PAPER_ASK_PROBABILITIES, PAPER_BLOCK_COUNTS, PAPER_DATA_COUNTS, TRIAL_COLUMNS
from .engine import Block, run, simulate
from .populations import SimulationError, Supervisors
from .results import SUMMARY_QUANTITIES, CrossoverSimulation, Simulation, participant_ids
from .trial_orders import schedule_counts


def simulate_design(
    model: TrustModel | Supervisors,
    n_participants: int,
    seed: int = 0,
    task: Task | None = None,
    n_trials: Sequence[int] = PAPER_DATA_COUNTS,
    p_ask: Sequence[float] = tuple(PAPER_ASK_PROBABILITIES.values()),
    p_unobserved: float = 0.0,
    rating_every: int = 0,
) -> pd.DataFrame:
    """Trial logs from ``model`` with the paper's design (Section V), in the canonical columns.

    Each participant does ``n_trials[c]`` trials of complexity c in random order under the
    ``randomized`` policy asking with ``p_ask[c]``; outcomes follow ``task`` (default: the paper
    task); the hidden trust at the start of each trial is the extra column ``true_trust``.
    ``model`` is one supervisor model or a :class:`Supervisors` population (participant ``i`` is
    its row ``i``).  ``p_unobserved`` blanks that fraction of human actions; ``rating_every`` > 0
    adds a ``rating`` column (:func:`add_ratings`) on every ``rating_every``-th trial.
    """
    task = task or paper_task()
    if isinstance(model, TrustModel):
        task.check_compatible(model)
    if len(p_ask) != task.n_complexity:
        raise SimulationError([f"p_ask needs one probability per complexity {list(task.complexities)}, got {list(p_ask)}"])
    policy = randomized(dict(zip(task.complexities, p_ask, strict=True)))
    trials = simulate(model, task, policy, n_participants, counts=n_trials, seed=seed).trials()
    frame = trials[[*TRIAL_COLUMNS, "true_trust"]].copy()
    if p_unobserved > 0:
        blank = np.random.default_rng(np.random.SeedSequence([seed, 1])).random(len(frame)) < p_unobserved
        frame.loc[blank, "human_action"] = None
    if rating_every > 0:
        if not isinstance(model, TrustModel):
            raise SimulationError(["ratings are drawn from one trust model's rating table, not from a population"])
        frame = add_ratings(frame, model, every=rating_every, seed=np.random.SeedSequence([seed, 2]))
    return frame


def add_ratings(
    frame: pd.DataFrame,
    model: TrustModel,
    every: int = 1,
    seed: int | np.random.SeedSequence = 0,
    column: str = "rating",
    trust: str = "true_trust",
) -> pd.DataFrame:
    """``frame`` with a self-reported rating column drawn from ``model``'s rating table given the
    hidden trust in column ``trust`` (P(rating | trust)), on every ``every``-th trial of each
    participant (trials ``every``, ``2 every``, ... in the order of the trial column; empty
    elsewhere).  The rating is an ordered categorical with the table's levels."""
    if model.rating is None:
        raise SimulationError(["the model has no rating table (P(rating | trust)) to draw ratings from"])
    if every < 1:
        raise SimulationError([f"every must be a positive number of trials, got {every}"])
    if trust not in frame.columns:
        raise SimulationError([f"the log has no hidden-trust column {trust!r} to draw ratings from"])
    levels = model.rating.levels
    k = pd.Series(frame[trust]).map({t: i for i, t in enumerate(model.trust_levels)})
    if k.isna().any():
        raise SimulationError([f"column {trust!r} holds values that are not trust levels {list(model.trust_levels)}"])
    cum = np.cumsum(np.asarray(model.rating.probs), axis=1)
    cum[:, -1] = 1.0
    u = np.random.default_rng(seed).random(len(frame))
    codes = (u[:, None] >= cum[k.to_numpy(dtype=np.int64)]).sum(axis=1)
    position = frame.groupby("participant", sort=False, observed=True)["trial"].rank(method="first").to_numpy()
    codes = np.where(position % every == 0, codes, -1)
    out = frame.copy()
    out[column] = pd.Categorical.from_codes(codes, categories=pd.Index(list(levels), dtype=object), ordered=True)
    return out


def crossover(
    model: TrustModel | Supervisors,
    task: Task,
    policies: Sequence[Policy],
    n_participants: int,
    counts: Sequence[int] | Mapping[str, int] = PAPER_BLOCK_COUNTS,
    first: Sequence[int] | np.ndarray | None = None,
    seed: int | np.random.SeedSequence = 0,
    record: bool = True,
    belief_model: TrustModel | None = None,
    compiled: bool = True,
) -> CrossoverSimulation:
    """The within-participant design of Section VI-B: every participant does one block per
    policy (``counts`` trials of each complexity in random order), in a counterbalanced order.

    ``first[i]`` is the policy participant ``i`` starts with; by default the rotations in turn
    (two policies, five participants: 3 start with the first, as in the paper).  Blocks are
    labelled by policy (``by_policy`` gives paired values); the trials' ``block`` column is the
    position.  ``compiled`` as in :func:`~trustseek.simulation.engine.run`.
    """
    sup = model if isinstance(model, Supervisors) else Supervisors.pooled(model, n_participants)
    n = sup.n
    P = len(policies)
    if P < 1:
        raise SimulationError(["crossover needs at least one policy"])
    starts = np.arange(n) % P if first is None else np.asarray(first, dtype=np.int64)
    if starts.shape != (n,) or starts.min() < 0 or starts.max() >= P:
        raise SimulationError([f"first must give, for each of the {n} participants, a policy index in 0..{P - 1}"])
    s_sched, s_run = seed_sequence(seed).spawn(2)
    rs = np.random.default_rng(s_sched)
    scheds = [schedule_counts(n, counts, rs, task.complexities, compiled=compiled) for _ in range(P)]
    labels = [getattr(p, "kind", f"policy {j + 1}") for j, p in enumerate(policies)]
    if len(set(labels)) != len(labels):
        labels = [f"{lab} {j + 1}" for j, lab in enumerate(labels)]
    ids = participant_ids(n)
    # one run per starting policy; participant streams come from one seed per order group
    group_seeds = s_run.spawn(P)
    parts = []
    for g in range(P):
        idx = np.flatnonzero(starts == g)
        if len(idx) == 0:
            continue
        order = [(g + k) % P for k in range(P)]
        blocks = [Block(policies[j], scheds[k][idx], name=labels[j], belief_model=belief_model) for k, j in enumerate(order)]
        sim = run(
            task,
            sup.take(idx),
            blocks,
            seed=group_seeds[g],
            record=record,
            participants=ids[idx],
            compiled=compiled,
        )
        parts.append((idx, order, sim))
    return _merge_crossover(task, sup, ids, labels, parts, record)


def _merge_crossover(
    task: Task,
    sup: Supervisors,
    ids: np.ndarray,
    labels: list[str],
    parts: list[tuple[np.ndarray, list[int], Simulation]],
    record: bool,
) -> CrossoverSimulation:
    """One simulation from the runs of the order groups: summary columns per policy and the
    participants in their original order."""
    n, P = len(ids), len(labels)
    summary = {k: np.zeros((n, P)) for k in SUMMARY_QUANTITIES}
    arrays: dict[str, np.ndarray] = {}
    lengths: list[int] = []
    orders = np.zeros((n, P), dtype=np.int64)
    for idx, order, sim in parts:
        for k in summary:
            summary[k][idx[:, None], np.array(order)[None, :]] = sim.summary_arrays[k]
        orders[idx] = order
        for k, v in (sim.arrays or {}).items():
            if k not in arrays:
                arrays[k] = np.empty((n, v.shape[1]), dtype=v.dtype)
            arrays[k][idx] = v
        lengths = sim.block_lengths
    return CrossoverSimulation(
        task=task,
        trust_levels=tuple(sup.trust_levels),
        participant_list=ids,
        block_labels=list(labels),
        block_lengths=list(lengths),
        summary_arrays=summary,
        arrays=arrays if record else None,
        orders=orders,
    )
