"""Where a policy asks, through the ``Policy`` interface: the simulator's threshold bounds and the
JSON view of a policy's ask regions."""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Policy
from .thresholds import threshold


def ask_bounds(policy: Policy) -> np.ndarray | None:
    """Per complexity index, the bound θ_C such that the policy asks exactly when
    P(trust = high) < θ_C (``-inf``: never asks, ``+inf``: always asks), or ``None`` when its
    ask region is not an interval starting at 0 or when it asks at random.

    This is the policy's ``actions`` in one comparison per trial (what the simulator uses);
    the bounds are the ends of ``ask_intervals()``, so both agree except for beliefs within
    rounding error of a crossing itself."""
    intervals = policy.ask_intervals()
    if intervals is None:
        return None
    out = []
    for cn in policy.complexities:
        iv = intervals[cn]
        th = threshold(iv)
        if th is None:
            out.append(-np.inf)
        elif np.isnan(th):
            return None
        else:
            out.append(np.inf if th >= 1.0 else th)
    return np.array(out)


def ask_regions(policy: Policy) -> dict[str, Any]:
    """Where a policy asks, ready for JSON: its ``thresholds`` and ``ask_intervals`` (as lists) per
    complexity (for a policy that asks at random: thresholds ``None``, no intervals)."""
    intervals = policy.ask_intervals() or {}
    return {"thresholds": policy.thresholds(), "ask_intervals": {k: [list(iv) for iv in v] for k, v in intervals.items()}}
