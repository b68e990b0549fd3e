"""Trial schedules: which complexity each participant meets on each trial.

Either fixed counts per complexity in a random order (the paper's designs: 41 low and 30
high trials in experiment 1, 17 and 17 per block in experiment 2) or i.i.d. complexities.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from . import kernels
from .populations import SimulationError, check_participants, check_size

SeedLike = np.random.Generator | np.random.SeedSequence | int | None


def schedule_counts(
    n: int,
    counts: Sequence[int] | Mapping[str, int],
    rng: SeedLike,
    complexities: Sequence[str] = ("low", "high"),
    compiled: bool = True,
) -> np.ndarray:
    """(n, T) complexity indices: each participant gets ``counts[c]`` trials of complexity ``c``
    in an independent random order (the paper: 41 low and 30 high; 17 and 17 per block).
    ``compiled``: two complexities run in :func:`.kernels.urn_schedule` (the same draws and the
    same schedule as the numpy loop, which ``compiled=False`` runs)."""
    check_participants(n)
    if isinstance(counts, Mapping):
        unknown = [k for k in counts if k not in complexities]
        if unknown:
            raise SimulationError([f"unknown complexity {unknown[0]!r} in counts; expected one of {list(complexities)}"])
        numbers = [int(counts.get(c, 0)) for c in complexities]
    else:
        numbers = [int(k) for k in counts]
    if len(numbers) != len(complexities) or any(k < 0 for k in numbers) or sum(numbers) < 1:
        raise SimulationError(
            [
                f"counts must give a non-negative number of trials for each of {list(complexities)} "
                f"with at least one trial in total, got {numbers}"
            ]
        )
    check_size(n, sum(numbers))
    # Drawing trial by trial from an urn holding the remaining trials of each complexity
    # gives every arrangement of the counts the same probability (vectorized over participants).
    gen = np.random.default_rng(rng)
    T, N = sum(numbers), len(numbers)
    out = np.empty((T, n), dtype=np.int8)
    if compiled and N == 2:
        kernels.urn_schedule(gen.random((T, n)), float(numbers[0]), out)  # = T successive random(n)
        return out.T
    remaining = [np.full(n, k, dtype=np.float64) for k in numbers]
    for t in range(T):
        x = gen.random(n)
        x *= T - t  # uniform over the trials left: below remaining[0] -> complexity 0, ...
        c = np.zeros(n, dtype=np.int8)
        edge = remaining[0].copy()
        for k in range(1, N):
            c += x >= edge
            edge += remaining[k]
        out[t] = c
        for k in range(N):
            remaining[k] -= c == k
    return out.T  # (n, T), stored trial-major: the simulator reads one trial of everyone at a time


def schedule_iid(n: int, trials: int, probs: Sequence[float] | np.ndarray, rng: SeedLike) -> np.ndarray:
    """(n, trials) complexity indices drawn i.i.d. from ``probs`` (e.g. ``Task.complexity_probs``)."""
    check_participants(n)
    if int(trials) != trials or trials < 1:
        raise SimulationError([f"the number of trials must be a positive integer, got {trials!r}"])
    check_size(n, trials)
    p = np.asarray(probs, dtype=float)
    u = np.random.default_rng(rng).random((int(trials), n))
    return np.searchsorted(np.cumsum(p)[:-1], u, side="right").astype(np.int8).T
