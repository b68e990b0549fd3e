"""The statistics module against independent references: the signed-rank p-value against a plain
transcription of its definition (mid-ranks by a loop, the distribution of W+ by full-array updates;
the same number to the last bit), the AUC against its pairwise definition, the weighted
correlations against scipy's on the repeated data."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from trustseek.statistics import EXACT_SIGNED_RANK, auc, correlations, signed_rank_p


def reference(d):
    d = np.asarray(d, dtype=float)
    d = d[d != 0]
    n = len(d)
    if n == 0:
        return 1.0
    a = np.abs(d)
    order = np.argsort(a, kind="stable")
    sa = a[order]
    ranks = np.empty(n)
    i = 0
    while i < n:
        j = i
        while j + 1 < n and sa[j + 1] == sa[i]:
            j += 1
        ranks[order[i : j + 1]] = (i + j + 2) / 2.0
        i = j + 1
    w2 = round(float(2 * ranks[d > 0].sum()))
    weights = np.rint(2 * ranks).astype(np.int64)
    counts = np.zeros(int(weights.sum()) + 1)
    counts[0] = 1.0
    for w in weights:
        counts[w:] = counts[w:] + counts[:-w].copy()
    probs = counts / counts.sum()
    return float(min(1.0, 2 * min(float(probs[: w2 + 1].sum()), float(probs[w2:].sum()))))


@settings(max_examples=80, deadline=None)
@given(st.lists(st.integers(-6, 6), min_size=0, max_size=EXACT_SIGNED_RANK), st.floats(0.1, 10.0))
def test_signed_rank_is_its_definition(values, scale):
    d = np.array(values, dtype=float) * scale  # small integers: many ties and zeros
    assert signed_rank_p(d) == reference(d)


def test_signed_rank_of_distinct_differences():
    """Without ties or zeros, also scipy's exact test (an implementation of its own)."""
    rng = np.random.default_rng(4)
    for n in (1, 2, 5, 30, EXACT_SIGNED_RANK):
        d = rng.normal(0.3, 1.0, n)
        assert signed_rank_p(d) == reference(d)
        assert signed_rank_p(d) == pytest.approx(stats.wilcoxon(d, method="exact").pvalue, rel=1e-12, abs=0)


def _auc_reference(s: np.ndarray, y: np.ndarray) -> float:
    try:
        from sklearn.metrics import roc_auc_score
    except ImportError:
        pos, neg = s[y == 1], s[y == 0]
        return float(((pos[:, None] > neg[None, :]).sum() + 0.5 * (pos[:, None] == neg[None, :]).sum()) / (len(pos) * len(neg)))
    return float(roc_auc_score(y, s))


@settings(max_examples=60, deadline=None)
@given(
    data=st.lists(st.tuples(st.integers(0, 6), st.booleans()), min_size=2, max_size=60).filter(
        lambda d: len({y for _, y in d}) == 2
    ),
    reps=st.lists(st.integers(0, 3), min_size=60, max_size=60),
)
def test_auc_matches_the_reference_with_ties_and_with_weights(data, reps):
    s = np.array([x / 6 for x, _ in data])
    y = np.array([float(v) for _, v in data])
    assert float(auc(s, y)) == pytest.approx(_auc_reference(s, y), abs=1e-12)
    w = np.array(reps[: len(s)], dtype=float)
    rs, ry = np.repeat(s, w.astype(int)), np.repeat(y, w.astype(int))
    expected = _auc_reference(rs, ry) if len(set(ry)) == 2 else np.nan
    got = float(auc(s, y, w[None])[0])
    assert (np.isnan(got) and np.isnan(expected)) or got == pytest.approx(expected, abs=1e-12)


@settings(max_examples=50, deadline=None)
@given(
    xs=st.lists(st.tuples(st.integers(0, 4), st.integers(0, 5)), min_size=4, max_size=30),
    reps=st.lists(st.integers(0, 3), min_size=30, max_size=30),
)
def test_weighted_correlations_are_those_of_the_repeated_data(xs, reps):
    x = np.array([a for a, _ in xs], dtype=float)
    y = np.array([b for _, b in xs], dtype=float)
    w = np.array(reps[: len(x)], dtype=float)
    got = correlations(x, y, w[None])
    rx, ry = np.repeat(x, w.astype(int)), np.repeat(y, w.astype(int))
    if len(rx) < 3 or np.ptp(rx) == 0 or np.ptp(ry) == 0:
        assert np.isnan(got["spearman"][0]) and np.isnan(got["pearson"][0])
        return
    assert got["spearman"][0] == pytest.approx(stats.spearmanr(rx, ry).statistic, abs=1e-9)
    assert got["pearson"][0] == pytest.approx(stats.pearsonr(rx, ry).statistic, abs=1e-9)
