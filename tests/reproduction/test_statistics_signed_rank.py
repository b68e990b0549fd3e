"""The signed-rank p-value against a plain transcription of its definition (mid-ranks by a loop,
the distribution of W+ by full-array updates): the same number to the last bit."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek.reproduction.statistics import EXACT_SIGNED_RANK, signed_rank_p


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
    rng = np.random.default_rng(4)
    for n in (1, 2, 5, 30, EXACT_SIGNED_RANK):
        d = rng.normal(0.3, 1.0, n)
        assert signed_rank_p(d) == reference(d)
