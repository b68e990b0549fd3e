"""Experiment designs on simulated supervisors: the paper's data collection (Section V)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..model.core import Task, TrustModel
from ..model.presets import paper_task
from ..policies import randomized
from ..vocab import PAPER_ASK_PROBABILITIES, PAPER_DATA_COUNTS, TRIAL_COLUMNS
from .engine import SimulationError, simulate


def simulate_design(
    model: TrustModel,
    n_participants: int,
    seed: int = 0,
    task: Task | None = None,
    n_trials: Sequence[int] = PAPER_DATA_COUNTS,
    p_ask: Sequence[float] = tuple(PAPER_ASK_PROBABILITIES.values()),
    p_unobserved: float = 0.0,
) -> pd.DataFrame:
    """Trial logs from ``model`` with the paper's design (Section V), in the canonical columns.

    Each participant does ``n_trials[c]`` trials of complexity c in random order, under
    the ``randomized`` policy that asks with probability ``p_ask[c]``; outcomes follow
    ``task`` (default: the paper task) and the experience rule of Section III.  This is
    the simulation engine's run of that policy; the hidden trust at the start of each
    trial is kept in the extra column ``true_trust``.  ``p_unobserved`` blanks that
    fraction of human actions (not recorded).
    """
    task = task or paper_task()
    task.check_compatible(model)
    if len(p_ask) != task.n_complexity:
        raise SimulationError([f"p_ask needs one probability per complexity {list(task.complexities)}, got {list(p_ask)}"])
    policy = randomized(dict(zip(task.complexities, p_ask, strict=True)))
    trials = simulate(model, task, policy, n_participants, counts=n_trials, seed=seed).trials()
    frame = trials[[*TRIAL_COLUMNS, "true_trust"]].copy()
    if p_unobserved > 0:
        blank = np.random.default_rng(np.random.SeedSequence([seed, 1])).random(len(frame)) < p_unobserved
        frame.loc[blank, "human_action"] = None
    return frame
