"""The statistics the reproduction reports: t intervals of means, exact binomial intervals of
shares, distributions over replicates and the paper's Wilcoxon signed-rank test."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

# scipy.stats takes about a second to import: it is imported where it is used, so that the
# command line starts fast


def mean_ci(values: Sequence[float] | np.ndarray, level: float = 0.95) -> tuple[float, float, float]:
    """Mean and its Student-t interval (exact for normal data, also for n = 5; NaN ends for
    fewer than two values)."""
    from scipy.stats import t as student_t

    v = np.asarray(values, dtype=float)
    m = float(v.mean())
    n = len(v)
    h = float(student_t.ppf(0.5 + level / 2, n - 1)) * float(v.std(ddof=1)) / math.sqrt(n) if n > 1 else float("nan")
    return m, m - h, m + h


def mean_interval(values: Sequence[float] | np.ndarray, level: float = 0.95) -> dict[str, float]:
    """:func:`mean_ci` as ``{"mean", "low", "high"}``."""
    m, lo, hi = mean_ci(values, level)
    return {"mean": m, "low": lo, "high": hi}


def share_ci(successes: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) interval of a share of ``successes`` out of ``n``."""
    from scipy.stats import binomtest

    ci = binomtest(int(successes), int(n)).proportion_ci(confidence_level=level, method="exact")
    return float(ci.low), float(ci.high)


def _finite(values: Iterable[float | None]) -> list[float]:
    return [float(x) for x in values if x is not None and np.isfinite(x)]


def percentile(values: Iterable[float | None], q: float) -> float | None:
    """The ``q``-th percentile of the finite values, or None when there are none."""
    v = _finite(values)
    return float(np.percentile(v, q)) if v else None


def distribution(values: Sequence[float | None]) -> dict[str, Any]:
    """Median, mean, min and max (the replicate range), central 95 % percentiles (rough for
    few values) of the finite values, and every value (None for a missing or non-finite one)."""
    vals = _finite(values)
    return {
        "n": len(vals),
        "min": min(vals) if vals else None,
        "max": max(vals) if vals else None,
        "median": percentile(vals, 50),
        "mean": float(np.mean(vals)) if vals else None,
        "p2.5": percentile(vals, 2.5),
        "p97.5": percentile(vals, 97.5),
        "values": [None if x is None or not np.isfinite(x) else float(x) for x in values],
    }


def wilcoxon(aware: np.ndarray, agnostic: np.ndarray) -> dict[str, Any]:
    """Two-sided Wilcoxon signed-rank test of the paired differences (scipy)."""
    d = np.asarray(aware, float) - np.asarray(agnostic, float)
    out: dict[str, Any] = {"n": len(d), "nonzero": int(np.count_nonzero(d))}
    if np.count_nonzero(d) == 0:
        out.update(statistic=None, p_value=None, note="all paired differences are zero")
        return out
    from scipy.stats import wilcoxon as scipy_wilcoxon

    res = scipy_wilcoxon(aware, agnostic, zero_method="wilcox", alternative="two-sided")
    out.update(statistic=float(res.statistic), p_value=float(res.pvalue))
    return out
