"""Experiment designs on simulated supervisors: the paper's data collection (Section V)."""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pandas as pd

from ..model.core import Task, TrustModel
from ..model.presets import paper_task
from ..vocab import ACTIONS, ASK, EXPERIENCES, HUMAN_ACTIONS, PAPER_ASK_PROBABILITIES, PAPER_DATA_COUNTS

def simulate_design(
    model: TrustModel,
    n_participants: int,
    seed: int = 0,
    task: Task | None = None,
    n_trials: Sequence[int] = PAPER_DATA_COUNTS,
    p_ask: Sequence[float] = tuple(PAPER_ASK_PROBABILITIES.values()),
    p_unobserved: float = 0.0,
) -> pd.DataFrame:
    """Trial logs from ``model`` with the paper's design (Section V).

    Each participant does ``n_trials[c]`` trials of complexity c in random order;
    the robot asks with probability ``p_ask[c]``; outcomes follow ``task``
    (default: the paper task) and the experience rule of Section III.  The hidden
    trust at the start of each trial is kept in the extra column ``true_trust``.
    ``p_unobserved`` blanks that fraction of human actions (not recorded).
    """
    task = task or paper_task()
    task.check_compatible(model)
    rng = np.random.default_rng(seed)
    N, C = int(n_participants), model.n_complexity
    comp = np.repeat(np.arange(C), n_trials)
    T = len(comp)
    cx = rng.permuted(np.tile(comp, (N, 1)), axis=1)
    K = model.n_trust
    trust = (rng.random(N)[:, None] > np.cumsum(model.initial)[None, :]).sum(1)
    trust = np.minimum(trust, K - 1)
    A = np.empty((N, T), dtype=np.int64)
    O = np.empty((N, T), dtype=np.int64)
    E = np.empty((N, T), dtype=np.int64)
    TR = np.empty((N, T), dtype=np.int64)
    pask = np.asarray(p_ask, dtype=float)
    ask_e = np.asarray(task.ask_experience)
    for t in range(T):
        c = cx[:, t]
        TR[:, t] = trust
        a = (rng.random(N) < pask[c]).astype(np.int64)
        o = np.where(rng.random(N) < model.emission[c, a, trust, 0], 0, 1)
        ok = rng.random(N) < task.success[c]
        e = np.where(a == ASK, ask_e[c], np.where(o == 0, 0, ok.astype(np.int64)))
        cum = np.cumsum(model.transition[c, a, e, trust], axis=1)
        nxt = (rng.random(N)[:, None] > cum).sum(1)
        trust = np.minimum(nxt, K - 1)
        A[:, t], O[:, t], E[:, t] = a, o, e
    ho = np.array(HUMAN_ACTIONS, dtype=object)[O].ravel()
    if p_unobserved > 0:
        ho[rng.random(N * T) < p_unobserved] = None
    return pd.DataFrame(
        {
            "participant": np.repeat([f"P{i + 1:03d}" for i in range(N)], T),
            "trial": np.tile(np.arange(1, T + 1), N),
            "complexity": np.array(model.complexities, dtype=object)[cx].ravel(),
            "robot_action": np.array(ACTIONS, dtype=object)[A].ravel(),
            "human_action": ho,
            "experience": np.array(EXPERIENCES, dtype=object)[E].ravel(),
            "true_trust": np.array(model.trust_levels, dtype=object)[TR].ravel(),
        }
    )
