"""Where a policy asks, as regions of belief: ask intervals and thresholds, extracted once.

For two trust levels a trust-aware policy asks where the advantage
D(x) = Q(x, C, ask) - Q(x, C, autonomous) is positive, x = P(trust = high).  The paper's
policies are *threshold* policies: they ask exactly when x < θ_C.  Every policy reports
its ask region through ``ask_intervals()``; :func:`ask_intervals` turns sampled advantages
into intervals and :func:`threshold` intervals into a threshold (:func:`.base.ask_bounds` and
:func:`.base.ask_regions` apply them to a policy).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

Interval = tuple[float, float]


def linear_crossing(x: np.ndarray, d: np.ndarray, i: int) -> float:
    """Where the line through (x[i], d[i]) and (x[i+1], d[i+1]) crosses zero."""
    d0, d1 = d[i], d[i + 1]
    if d0 == d1:
        return float(x[i])
    return float(x[i] + d0 / (d0 - d1) * (x[i + 1] - x[i]))


def ask_intervals(x: np.ndarray, advantage: np.ndarray, crossing: Callable[[int], float] | None = None) -> list[Interval]:
    """The maximal intervals of [x[0], x[-1]] where the advantage of asking is positive, from
    its values at the increasing points ``x``.  An interval ends at a sample end point or,
    between samples i and i + 1 where the sign changes, at ``crossing(i)`` (by default the
    zero of the line through the two samples: exact for piecewise-linear advantages)."""
    x = np.asarray(x, dtype=float)
    d = np.asarray(advantage, dtype=float)
    cross = crossing or (lambda i: linear_crossing(x, d, i))
    n = len(x)
    edges = np.flatnonzero(np.diff(np.concatenate([[False], d > 0, [False]]).astype(np.int8)))  # starts, ends of runs
    return [
        (float(x[0] if i == 0 else cross(i - 1)), float(x[-1] if j == n else cross(j - 1)))
        for i, j in zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True)
    ]


def threshold(intervals: Sequence[Interval], start: float = 0.0) -> float | None:
    """The belief in high trust below which a policy with these ask intervals asks: ``None``
    when it never asks, the upper end when it asks on one interval [start, θ) (1.0 when it
    always asks), NaN when its ask region is not of that form (see the intervals)."""
    if not intervals:
        return None
    if len(intervals) == 1 and intervals[0][0] == start:
        return float(intervals[0][1])
    return float("nan")
