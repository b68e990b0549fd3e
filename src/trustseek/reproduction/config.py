"""What the reproduction runs with, and what the paper reported.

:class:`ReproduceConfig` holds every setting of :func:`~trustseek.reproduction.reproduce`
(the defaults are the paper's design); :data:`PAPER` the numbers the paper reports that are
not parameters of the trust model (those are in :mod:`.comparison`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..parallel import MAX_JOBS
from ..vocab import (
    BELIEF_UPDATES,
    PAPER_ASK_PROBABILITIES,
    PAPER_BLOCK_COUNTS,
    PAPER_DATA_COUNTS,
    PAPER_DATA_PARTICIPANTS,
    PAPER_EVALUATION_PARTICIPANTS,
    TRUST_AGNOSTIC,
    TRUST_AWARE,
)

# indices of the paper's two trust and complexity levels
LOW, HIGH = 0, 1
# labels of the two policies of experiment 2
AWARE, AGNOSTIC = TRUST_AWARE, TRUST_AGNOSTIC

PAPER = {
    "threshold_high": 0.75,
    "median_aware": 57.0,
    "median_agnostic": 51.0,
    "participants_1": PAPER_DATA_PARTICIPANTS,
    "participants_2": PAPER_EVALUATION_PARTICIPANTS,
}


#: the lowest value of each counting setting, in the order :meth:`ReproduceConfig.problems` checks them
LOWEST = {
    "replicates": 0,
    **dict.fromkeys(
        ("large_n", "participants_1", "participants_2", "restarts", "replicate_restarts", "replicate_large_n", "jobs"), 1
    ),
    **dict.fromkeys(("sensitivity_samples", "schedule_participants", "types_participants", "bootstrap"), 0),
}


@dataclass
class ReproduceConfig:
    """Every setting of the reproduction (the defaults are the paper's design)."""

    seed: int = 0
    replicates: int = 20
    large_n: int = 10_000
    participants_1: int = PAPER_DATA_PARTICIPANTS
    counts_1: tuple[int, int] = PAPER_DATA_COUNTS
    ask_low: float = PAPER_ASK_PROBABILITIES["low"]
    ask_high: float = PAPER_ASK_PROBABILITIES["high"]
    participants_2: int = PAPER_EVALUATION_PARTICIPANTS
    counts_2: tuple[int, int] = PAPER_BLOCK_COUNTS
    restarts: int = 10
    bootstrap: int = 200
    replicate_restarts: int = 4
    replicate_large_n: int = 2_000
    belief_update: str = "paper"
    grid: int = 1001
    concentration: float = 20.0
    pseudo: float = 0.5
    jobs: int = 2
    sensitivity_samples: int = 200
    schedule_participants: int = 10_000  # simulated participants of the scheduling section (0: no section)
    types_participants: int = 2_000  # simulated participants of the supervisor-types section (0: no section)

    def problems(self) -> list[str]:
        """Every setting out of range, as a message naming its command-line option."""
        p = []
        for name, low in LOWEST.items():
            if getattr(self, name) < low:
                p.append(f"--{name.replace('_', '-')} must be >= {low}, got {getattr(self, name)}")
        if self.belief_update not in BELIEF_UPDATES:
            p.append(f"--belief-update must be 'paper' or 'bayes', got {self.belief_update!r}")
        if not (0 <= self.ask_low <= 1 and 0 <= self.ask_high <= 1):
            p.append("ask probabilities must lie in [0, 1]")
        if self.grid < 3:
            p.append(f"--grid must be >= 3, got {self.grid}")
        if self.jobs > MAX_JOBS:
            p.append(f"--jobs must be between 1 and {MAX_JOBS} worker processes, got {self.jobs}")
        return p

    def to_summary(self) -> dict[str, Any]:
        """The settings as recorded in summary.json (``jobs`` left out: it changes no number)."""
        d = asdict(self)
        d["counts_1"] = list(self.counts_1)
        d["counts_2"] = list(self.counts_2)
        d.pop("jobs")
        return d


def seed_int(ss: np.random.SeedSequence) -> int:
    """One 32-bit integer seed drawn from ``ss`` (for the functions that take an integer seed)."""
    return int(ss.generate_state(1, dtype=np.uint32)[0])
