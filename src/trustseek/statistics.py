"""The statistics every report gives, in one place: t intervals of means, exact binomial
intervals of shares, distributions over replicates, participant-bootstrap resamples and their
percentile intervals, AUC and weighted correlations (a bootstrap's counts as weights), the paper's
Wilcoxon signed-rank test (scipy's) and the design study's paired tests (an exact signed-rank
distribution with ties, and the paired t-test)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

#: up to this many nonzero differences the design study's signed-rank p-value is exact
EXACT_SIGNED_RANK = 60
LEVEL = 0.95  # the level of every interval unless a caller says otherwise
OUTSIDE = 1e-9  # an estimate this close to its percentile interval is not outside it

# scipy.stats takes about a second to import: it is imported where it is used, so that the
# command line starts fast


def mean_ci(values: Sequence[float] | np.ndarray, level: float = LEVEL) -> tuple[float, float, float]:
    """Mean and its Student-t interval (exact for normal data, also for n = 5; NaN ends for
    fewer than two values)."""
    from scipy.stats import t as student_t

    v = np.asarray(values, dtype=float)
    m = float(v.mean())
    n = len(v)
    h = float(student_t.ppf(0.5 + level / 2, n - 1)) * float(v.std(ddof=1)) / math.sqrt(n) if n > 1 else float("nan")
    return m, m - h, m + h


def mean_interval(
    values: Sequence[float] | np.ndarray, level: float = LEVEL, names: tuple[str, str, str] = ("mean", "low", "high")
) -> dict[str, float]:
    """:func:`mean_ci` as a dict keyed by ``names`` (the reproduction's reports use both spellings)."""
    return dict(zip(names, mean_ci(values, level), strict=True))


def share_ci(successes: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Exact (Clopper-Pearson) interval of a share of ``successes`` out of ``n``."""
    from scipy.stats import binomtest

    ci = binomtest(int(successes), int(n)).proportion_ci(confidence_level=level, method="exact")
    return float(ci.low), float(ci.high)


def finite(values: Iterable[float | None]) -> list[float]:
    """The finite values as floats (None, NaN and infinities left out)."""
    return [float(x) for x in values if x is not None and np.isfinite(x)]


def percentile(values: Iterable[float | None], q: float) -> float | None:
    """The ``q``-th percentile of the finite values, or None when there are none."""
    v = finite(values)
    return float(np.percentile(v, q)) if v else None


def distribution(values: Sequence[float | None]) -> dict[str, Any]:
    """Median, mean, min and max (the replicate range), central 95 % percentiles (rough for
    few values) of the finite values, and every value (None for a missing or non-finite one)."""
    vals = finite(values)
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


# --------------------------------------------------------------------------- bootstrap


def percentile_interval(values: np.ndarray, level: float = LEVEL) -> tuple[float, float]:
    """The central ``level`` percentile interval of the finite ``values`` (NaN, NaN: none)."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return float("nan"), float("nan")
    lo, hi = np.percentile(v, [100 * (1 - level) / 2, 100 * (1 + level) / 2])
    return float(lo), float(hi)


def bootstrap_counts(n_participants: int, replicates: int, seed: int) -> np.ndarray:
    """(B, N): how often each participant is drawn in each participant-bootstrap resample."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7]))
    if replicates <= 0 or n_participants == 0:
        return np.zeros((0, n_participants), dtype=np.int64)
    return rng.multinomial(n_participants, np.full(n_participants, 1.0 / n_participants), size=replicates)


def percentile_bounds(flat: np.ndarray, est: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The percentile interval at ``level`` of the replicates ``flat`` (B, cells), widened to contain the
    estimate ``est``, and where it had to be."""
    alpha = (1 - level) / 2
    lo, hi = np.quantile(flat, [alpha, 1 - alpha], axis=0)
    # outside by more than rounding: a cell on the stick-breaking boundary sits at 1e-12 times the
    # row's free mass, which differs between the estimate and a replicate in the 17th decimal
    widened = (est < lo - OUTSIDE) | (est > hi + OUTSIDE)
    return np.minimum(lo, est), np.maximum(hi, est), widened


def paired(estimate: float, reps: np.ndarray, lower_is_better: bool = False, ours: str = "model") -> dict[str, Any]:
    """A difference ``ours`` - baseline: its ``estimate``, the percentile interval of its resamples ``reps``
    and which of the two is better (``neither`` where the interval includes 0)."""
    lo, hi = percentile_interval(reps)
    better = "neither"
    if np.isfinite(lo) and np.isfinite(hi):
        good, bad = (hi < 0, lo > 0) if lower_is_better else (lo > 0, hi < 0)
        better = ours if good else "baseline" if bad else "neither"
    return {"estimate": estimate, "lower": lo, "upper": hi, "better": better}


# --------------------------------------------------------------------------- scores


def auc(scores: np.ndarray, labels: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Area under the ROC curve by the rank formula (a tie between a positive and a negative
    counts one half); ``weights`` (n,) or (B, n) weigh the trials (a bootstrap's counts):
    one AUC per row of weights.  NaN when a class is absent."""
    scores = np.asarray(scores, dtype=float)
    y = np.asarray(labels, dtype=float)
    w = np.ones_like(scores) if weights is None else np.asarray(weights, dtype=float)
    if scores.size == 0:
        return np.full(w.shape[:-1], np.nan)
    order = np.argsort(scores, kind="stable")
    s, y, w = scores[order], y[order], w[..., order]
    starts = np.flatnonzero(np.r_[True, s[1:] != s[:-1]])
    pos = np.add.reduceat(w * y, starts, axis=-1)
    neg = np.add.reduceat(w * (1.0 - y), starts, axis=-1)
    below = np.cumsum(neg, axis=-1) - neg
    num = (pos * (below + 0.5 * neg)).sum(-1)
    den = pos.sum(-1) * neg.sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


def _weighted_ranks(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Mid-ranks of ``x`` in the data where element i appears ``w[b, i]`` times, (B, n)."""
    order = np.argsort(x, kind="stable")
    xs = x[order]
    starts = np.flatnonzero(np.r_[True, xs[1:] != xs[:-1]])
    group = np.cumsum(np.r_[True, xs[1:] != xs[:-1]]) - 1
    g = np.add.reduceat(w[:, order], starts, axis=1)  # (B, G)
    mid = np.cumsum(g, axis=1) - g + (g + 1) / 2
    ranks = np.empty_like(w, dtype=float)
    ranks[:, order] = mid[:, group]
    return ranks


def _weighted_pearson(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Pearson correlation for every row of weights; x, y are (n,) or (B, n)."""
    W = w.sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx = (w * x).sum(-1) / W
        my = (w * y).sum(-1) / W
        dx = x - mx[:, None]
        dy = y - my[:, None]
        sxy = (w * dx * dy).sum(-1)
        sxx = (w * dx * dx).sum(-1)
        syy = (w * dy * dy).sum(-1)
        # a constant variable (up to rounding) has no correlation
        ok = (sxx > 1e-12 * (w * x * x).sum(-1) + 1e-300) & (syy > 1e-12 * (w * y * y).sum(-1) + 1e-300) & (W >= 3)
        return np.where(ok, sxy / np.sqrt(np.where(ok, sxx * syy, 1.0)), np.nan)


def correlations(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> dict[str, np.ndarray]:
    """Spearman and Pearson correlations of ``x`` and ``y`` (n,) for every row of weights (B, n)."""
    if x.size == 0:
        nan = np.full(w.shape[0], np.nan)
        return {"spearman": nan, "pearson": nan}
    return {
        "spearman": _weighted_pearson(_weighted_ranks(x, w), _weighted_ranks(y, w), w),
        "pearson": _weighted_pearson(x, y, w),
    }


# --------------------------------------------------------------------------- tests


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
