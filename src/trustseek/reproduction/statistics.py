"""The statistics the reproduction and the design study report: t intervals of means, exact
binomial intervals of shares, distributions over replicates, the paper's Wilcoxon signed-rank
test (scipy's) and the design study's paired tests (an exact signed-rank distribution with
ties, and the paired t-test)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

#: up to this many nonzero differences the design study's signed-rank p-value is exact
EXACT_SIGNED_RANK = 60

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


def signed_rank_p(d: np.ndarray) -> float:
    """Two-sided p-value of the Wilcoxon signed-rank test of the paired differences ``d``
    (zeros dropped, ties given their mid-ranks).  Exact up to :data:`EXACT_SIGNED_RANK` nonzero
    differences: the distribution of W+ over the 2^n sign patterns, by dynamic programming on
    the doubled mid-ranks (integers); beyond, the normal approximation with the tie correction.
    1 when every difference is zero."""
    d = np.asarray(d, dtype=float)
    d = d[d != 0]
    n = len(d)
    if n == 0:
        return 1.0
    a = np.abs(d)
    order = np.argsort(a, kind="stable")
    sa = a[order]
    first = np.flatnonzero(np.concatenate(([True], sa[1:] != sa[:-1])))  # where each run of tied |d| starts
    last = np.append(first[1:], n) - 1
    ranks = np.empty(n)
    ranks[order] = np.repeat((first + last + 2) / 2.0, last - first + 1)  # mid-ranks
    w2 = round(float(2 * ranks[d > 0].sum()))  # doubled W+
    if n > EXACT_SIGNED_RANK:
        mean = n * (n + 1) / 4.0
        tie_counts = last - first + 1
        var = n * (n + 1) * (2 * n + 1) / 24.0 - float(np.sum(tie_counts**3 - tie_counts)) / 48.0
        z = (w2 / 2.0 - mean) / np.sqrt(var)
        from scipy.stats import norm

        return float(min(1.0, 2 * norm.sf(abs(z))))
    weights = np.rint(2 * ranks).astype(np.int64)
    counts = np.zeros(int(weights.sum()) + 1)
    counts[0] = 1.0
    for w in weights:  # times (1 + z^w): the number of sign patterns giving each doubled W+
        counts[w:] = counts[w:] + counts[:-w]
    probs = counts / counts.sum()
    low = float(probs[: w2 + 1].sum())
    high = float(probs[w2:].sum())
    return float(min(1.0, 2 * min(low, high)))


def paired_tests(aware: np.ndarray, agnostic: np.ndarray) -> dict[str, float]:
    """Two-sided p-values of the paired Wilcoxon signed-rank test and the paired t-test, and the
    mean paired difference (p = 1 when every difference is zero: nothing to detect)."""
    d = np.asarray(aware, float) - np.asarray(agnostic, float)
    out = {"mean_difference": float(d.mean())}
    if not np.any(d):
        return out | {"wilcoxon": 1.0, "t": 1.0}
    w = signed_rank_p(d)
    # constant nonzero differences: the t statistic is infinite (p = 0 from two participants on)
    constant = len(d) < 2 or bool(np.all(d == d[0]))
    t = (0.0 if len(d) > 1 else 1.0) if constant else _t_p(d)
    return out | {"wilcoxon": w, "t": t}


def _t_p(d: np.ndarray) -> float:
    """Two-sided p-value of the paired t-test on the differences ``d`` (at least two, not all equal):
    ``scipy.stats.ttest_rel``'s, from Student's t distribution directly."""
    from scipy.special import stdtr

    n = len(d)
    t = float(d.mean()) / (float(d.std(ddof=1)) / np.sqrt(n))
    return float(2.0 * stdtr(n - 1, -abs(t)))
