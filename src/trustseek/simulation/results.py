"""What a simulation produced: per-participant summaries per block and, when recorded, every trial.

:class:`Simulation` holds one summary column per block (in the order done);
:class:`CrossoverSimulation` one per policy, with each participant's order, so that ``by_policy``
gives paired values.  A trial's recorded trust is the trust at its start; ``belief`` is the
robot's P(trust = highest level) when it chose the action.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..model.task import Task
from ..vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS
from .populations import SimulationError

SUMMARY_COLUMNS = (
    "participant",
    "block",
    "policy",
    "trials",
    "cumulative_reward",
    "discounted_reward",
    "autonomous_collections",
    "failures",
    "interventions",
    "asks",
)
# the per-participant quantities summed over a block
SUMMARY_QUANTITIES = SUMMARY_COLUMNS[4:]


def participant_ids(n: int) -> np.ndarray:
    """Ids ``p001``, ``p002``, ... (zero-padded to sort in order)."""
    width = max(3, len(str(n)))
    return np.array([f"p{i:0{width}d}" for i in range(1, n + 1)], dtype=object)


@dataclass
class Simulation:
    """What a simulation produced: per-participant summaries and (when recorded) every trial."""

    task: Task
    trust_levels: tuple[str, ...]
    participant_list: np.ndarray | None  # (n,) string ids, or None for p001, p002, ...
    block_labels: list[str]
    block_lengths: list[int]
    summary_arrays: dict[str, np.ndarray]  # name -> (n, n_blocks)
    arrays: dict[str, np.ndarray] | None = None  # name -> (n, T_total), when recorded

    @property
    def n(self) -> int:
        return next(iter(self.summary_arrays.values())).shape[0]

    @property
    def participants(self) -> np.ndarray:
        """(n,) participant ids."""
        if self.participant_list is None:
            self.participant_list = participant_ids(self.n)
        return self.participant_list

    def block_of_trial(self) -> np.ndarray:
        """(T_total,) 1-based block number of every trial position."""
        return np.repeat(np.arange(1, len(self.block_lengths) + 1), self.block_lengths)

    def summary(self) -> pd.DataFrame:
        """One row per participant and block: cumulative (and discounted) reward, autonomous
        collections (autonomous successes), failures, interventions and asks."""
        n, nb = self.n, len(self.block_labels)
        out = {
            "participant": np.repeat(self.participants, nb),
            "block": np.tile(np.arange(1, nb + 1), n),
            "policy": np.tile(np.array(self.block_labels, dtype=object), n),
            "trials": np.tile(np.array(self.block_lengths), n),
        }
        for k in SUMMARY_QUANTITIES:
            v = self.summary_arrays[k].reshape(-1)
            out[k] = v if k in ("cumulative_reward", "discounted_reward") else v.astype(np.int64)
        return pd.DataFrame(out, columns=list(SUMMARY_COLUMNS))

    def reward_matrix(self, key: str = "cumulative_reward") -> np.ndarray:
        """(n, n_blocks) array of a summary quantity."""
        return self.summary_arrays[key]

    def by_policy(self, key: str = "cumulative_reward") -> dict[str, np.ndarray]:
        """Per policy label, the (n,) values of ``key`` (summed over that policy's blocks)."""
        out: dict[str, np.ndarray] = {}
        for j, lab in enumerate(self.block_labels):
            column = self.summary_arrays[key][:, j]
            out[lab] = out[lab] + column if lab in out else column.copy()
        return out

    def trials(self) -> pd.DataFrame:
        """Every trial in the canonical trial-log format (``participant, trial, complexity,
        robot_action, human_action, experience``) followed by ``block, policy, true_trust,
        belief, reward``."""
        if self.arrays is None:
            raise SimulationError(["this simulation did not record trials (record=False)"])
        a = self.arrays
        n, T = a["complexity"].shape
        blocks = self.block_of_trial()
        return pd.DataFrame(
            {
                "participant": _labels(self.participants, np.repeat(np.arange(n), T)),
                "trial": np.tile(np.arange(1, T + 1), n),
                "complexity": _labels(self.task.complexities, a["complexity"]),
                "robot_action": _labels(ACTIONS, a["action"]),
                "human_action": _labels(HUMAN_ACTIONS, a["human"]),
                "experience": _labels(EXPERIENCES, a["experience"]),
                "block": np.tile(blocks, n),
                "policy": _labels(self.block_labels, np.tile(blocks - 1, n)),
                "true_trust": _labels(self.trust_levels, a["trust"]),
                "belief": a["belief"].reshape(-1),
                "reward": a["reward"].reshape(-1),
            }
        )


@dataclass
class CrossoverSimulation(Simulation):
    """A :class:`Simulation` whose summary columns are per policy (not per position); ``orders[i]``
    lists the policy indices in the order participant ``i`` met them."""

    orders: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=np.int64))

    def summary(self) -> pd.DataFrame:
        s = super().summary()
        pos = np.argsort(self.orders, axis=1) + 1  # position of each policy for each participant
        s["block"] = pos.reshape(-1)
        return s

    def trials(self) -> pd.DataFrame:
        frame = super().trials()
        pos = self.block_of_trial() - 1  # position of each trial (blocks have equal lengths)
        frame["policy"] = _labels(self.block_labels, self.orders[:, pos])
        return frame


def _labels(levels: Sequence[str] | np.ndarray, codes: np.ndarray) -> pd.Index:
    """The text of ``codes`` (any shape, read row by row) into ``levels``, made without a Python
    string per trial."""
    return pd.Index(levels, dtype="str").take(np.asarray(codes, dtype=np.intp).reshape(-1))
