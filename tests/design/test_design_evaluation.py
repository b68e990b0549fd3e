"""The exact evaluation's chain matrix, made all at once, against the entry-by-entry construction."""

import numpy as np
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek import TrustModel, paper_task, trust_model
from trustseek.design.evaluation import _ask_probabilities, _chain_matrix, evaluate_policy
from trustseek.policies import TrustAwarePolicy
from trustseek.pomdp.belief import ScalarBelief
from trustseek.pomdp.problem import AssistancePOMDP

TASK = paper_task()


def random_model(seed: int, ask_informative: bool) -> TrustModel:
    rng = np.random.default_rng(seed)
    em = rng.uniform(0.05, 0.95, size=(2, 2, 2))
    if not ask_informative:
        em[:, 1] = 1.0  # asked supervisors always intervene (zero kernel entries)
    tr = rng.dirichlet([2.0, 2.0], size=(2, 2, 2, 2))
    return trust_model(("low", "high"), ("low", "high"), rng.dirichlet([2.0, 2.0]), np.stack([em, 1 - em], -1), tr)


def reference_matrix(step, kernel, w, gamma, xs):
    """The matrix entry by entry: for each (C, a, o, E') one belief step, for each (T, T') the two
    interpolation weights of every grid point."""
    G = len(xs)
    rows, cols, vals = [], [], []
    idx = np.arange(G)
    for c in range(w.shape[0]):
        for a in range(2):
            if not np.any(w[c, a]):
                continue
            ca = np.full(G, c * 2 + a, dtype=np.int64)
            for o in range(2):
                for e in range(2):
                    nxt = step.step(xs, ca, np.full(G, o, dtype=np.int64), np.full(G, e, dtype=np.int64))
                    pos = np.clip(nxt, 0.0, 1.0) * (G - 1)
                    j = np.minimum(np.floor(pos).astype(np.int64), G - 2)
                    f = pos - j
                    for t in range(2):
                        for u in range(2):
                            p = kernel[c, a, t, o, e, u]
                            if p > 0:
                                base = gamma * p * w[c, a]
                                rows += [t * G + idx, t * G + idx]
                                cols += [u * G + j, u * G + j + 1]
                                vals += [base * (1.0 - f), base * f]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * G, 2 * G))


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    informative=st.booleans(),
    update=st.sampled_from(["paper", "bayes"]),
    grid=st.integers(3, 60),
    bounds=st.tuples(st.sampled_from([-1.0, 0.0, 0.3, 0.7, 2.0]), st.sampled_from([-1.0, 0.45, 0.8, 2.0])),
)
def test_chain_matrix_is_the_entry_by_entry_one(seed, informative, update, grid, bounds):
    truth = random_model(seed, informative)
    own = random_model(seed + 1, True)
    g = np.linspace(0.0, 1.0, 41)
    q = np.zeros((len(g), 2, 2))
    for c, th in enumerate(bounds):
        q[:, c, 1] = th - g
    policy = TrustAwarePolicy(g, q, own, TASK.complexities, update)
    pomdp = AssistancePOMDP(truth, TASK)
    xs = np.linspace(0.0, 1.0, grid)
    p_ask = _ask_probabilities(policy, xs, 2)
    w = pomdp.complexity_probs[:, None, None] * np.stack([1.0 - p_ask, p_ask], axis=1)
    step = ScalarBelief(own, update)
    got = _chain_matrix(step, pomdp.kernel, w, w.any(axis=2), pomdp.discount, xs)
    want = reference_matrix(step, pomdp.kernel, w, pomdp.discount, xs)
    # the same entries in the same order: the same matrix to the last bit, so the same values
    np.testing.assert_array_equal(got.indptr, want.indptr)
    np.testing.assert_array_equal(got.indices, want.indices)
    np.testing.assert_array_equal(got.data, want.data)
    value = evaluate_policy(policy, truth, TASK, grid=grid).value
    assert np.isfinite(value)
