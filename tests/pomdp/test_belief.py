"""Belief updates: eq. (3) and the exact Bayes filter."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek import BayesUpdate, PaperUpdate, paper_model
from trustseek.vocab import ASK, AUTONOMOUS, FAULTY, INTERVENE, RELIABLE, RELY

LOW, HIGH = 0, 1


def test_paper_update_is_eq3(model):
    up = PaperUpdate(model)
    b = np.array([0.4, 0.6])
    # eq. (3): b' = P(H | H, E', C, a) b + P(H | L, E', C, a) (1 - b)
    out = up.update(b, HIGH, ASK, INTERVENE, RELIABLE)
    assert out[1] == pytest.approx(0.94 * 0.6 + 0.44 * 0.4)
    # the human action is ignored
    np.testing.assert_array_equal(up.update(b, HIGH, AUTONOMOUS, RELY, FAULTY), up.update(b, HIGH, AUTONOMOUS, INTERVENE, FAULTY))


def test_bayes_update_by_hand(model):
    up = BayesUpdate(model)
    b = np.array([0.4, 0.6])
    # an intervention in high complexity is evidence of low trust: P(int | L) = 0.54, P(int | H) = 0.05
    post_h = 0.6 * 0.05 / (0.6 * 0.05 + 0.4 * 0.54)
    out = up.update(b, HIGH, AUTONOMOUS, INTERVENE, FAULTY)
    # then the faulty-experience transition in high complexity: H -> L w.p. 1, L stays L w.p. 0.7
    assert out[1] == pytest.approx(post_h * 0.0 + (1 - post_h) * 0.3)
    # relying is evidence of high trust
    post_h = 0.6 * 0.95 / (0.6 * 0.95 + 0.4 * 0.46)
    out = up.update(b, HIGH, AUTONOMOUS, RELY, FAULTY)
    assert out[1] == pytest.approx((1 - post_h) * 0.3)
    # when asked the human always teleoperates: no information, same as eq. (3)
    paper = PaperUpdate(model).update(b, HIGH, ASK, INTERVENE, RELIABLE)
    np.testing.assert_allclose(up.update(b, HIGH, ASK, INTERVENE, RELIABLE), paper)


def test_unobserved_and_impossible_actions(model):
    up = BayesUpdate(model)
    b = np.array([0.4, 0.6])
    paper = PaperUpdate(model).update(b, HIGH, AUTONOMOUS, RELY, RELIABLE)
    np.testing.assert_allclose(up.update(b, HIGH, AUTONOMOUS, -1, RELIABLE), paper)
    # 'rely' when asked has probability 0 under the paper model: the prior is kept
    np.testing.assert_allclose(up.update(b, HIGH, ASK, RELY, RELIABLE), PaperUpdate(model).update(b, HIGH, ASK, RELY, RELIABLE))


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 20),
    seed=st.integers(0, 2**32 - 1),
    which=st.sampled_from(["bayes", "paper"]),
)
def test_vectorized_equals_scalar_and_stays_a_distribution(n, seed, which):
    model = paper_model()
    rng = np.random.default_rng(seed)
    up = BayesUpdate(model) if which == "bayes" else PaperUpdate(model)
    bh = rng.random(n)
    b = np.stack([1 - bh, bh], axis=1)
    c, a, o, e = (rng.integers(0, 2, n) for _ in range(4))
    out = up.update(b, c, a, o, e)
    assert out.shape == (n, 2)
    np.testing.assert_allclose(out.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(out >= 0)
    for i in range(n):
        np.testing.assert_allclose(out[i], up.update(b[i], c[i], a[i], o[i], e[i]), atol=1e-15)


# --------------------------------------------------------------------------- every successor


def _interior_pomdp(K, seed=4):
    """A random model and task with every probability strictly inside (0, 1)."""
    from trustseek import AssistancePOMDP, paper_task, trust_model

    rng = np.random.default_rng(seed)
    m = trust_model(
        tuple(f"t{k}" for k in range(K)),
        ("low", "high"),
        rng.dirichlet(np.ones(K)),
        rng.dirichlet(np.ones(2), size=(2, 2, K)),
        rng.dirichlet(np.ones(K), size=(2, 2, 2, K)),
    )
    return AssistancePOMDP(m, paper_task())


@pytest.mark.parametrize("K", [2, 3])
@pytest.mark.parametrize("which", ["bayes", "paper"])
def test_branches_are_the_updaters_with_their_probabilities(K, which):
    """Each branch's next belief is the observed-trial update, and the branch probabilities are
    P(o, E' | b) (bayes) or P(E' | b) (paper), summing to one over the branches."""
    pomdp = _interior_pomdp(K)
    up = BayesUpdate(pomdp.model) if which == "bayes" else PaperUpdate(pomdp.model)
    B = np.random.default_rng(5).dirichlet(np.ones(K), size=50)
    n = len(B)
    branches = pomdp.branches(which)
    for c in range(2):
        for a in range(2):
            p, nxt = branches.successors(B, c, a)
            np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-12)
            for o in range(2):
                for e in range(2):
                    p_oe = (B @ pomdp.emission[c, a, :, o]) * pomdp.experience[c, a, o, e]
                    want = up.update(B, np.full(n, c), np.full(n, a), np.full(n, o), np.full(n, e))
                    br = o * 2 + e if which == "bayes" else e
                    if which == "paper" or np.all(p_oe > 0):  # (the task rules some (o, E') out)
                        np.testing.assert_allclose(nxt[:, br], want, atol=1e-12)
                    if which == "bayes":
                        np.testing.assert_allclose(p[:, br], p_oe, atol=1e-12)
            if which == "paper":
                for e in range(2):
                    p_e = sum((B @ pomdp.emission[c, a, :, o]) * pomdp.experience[c, a, o, e] for o in range(2))
                    np.testing.assert_allclose(p[:, e], p_e, atol=1e-12)
    # all (c, a) at once: the same arrays
    p_all, nxt_all = branches.successors(B)
    p, nxt = branches.successors(B, 1, 0)
    np.testing.assert_allclose(p_all[:, 1, 0], p, atol=1e-15)
    np.testing.assert_allclose(nxt_all[:, 1, 0], nxt, atol=1e-15)


@pytest.mark.parametrize("which", ["bayes", "paper"])
def test_two_level_maps_give_the_successors(which):
    pomdp = _interior_pomdp(2)
    branches = pomdp.branches(which)
    p0, p1, m0, m1 = branches.two_level()
    x = np.linspace(0, 1, 101)
    p, nxt = branches.successors(np.stack([1 - x, x], axis=1))
    prob = p0[None] * (1 - x)[:, None, None, None] + p1[None] * x[:, None, None, None]
    lin = m0[None] * (1 - x)[:, None, None, None] + m1[None] * x[:, None, None, None]
    np.testing.assert_allclose(p, prob, atol=1e-14)
    possible = prob > 0  # (the task rules some (o, E') out)
    want = np.divide(lin, prob, out=np.zeros_like(lin), where=possible) if which == "bayes" else lin
    np.testing.assert_allclose(nxt[..., 1][possible], want[possible], atol=1e-12)


def test_impossible_branches_lead_to_a_distribution(model):
    """'rely' when asked has probability 0 under the paper model: its branches have probability 0
    and still a next belief that is a distribution."""
    from trustseek import AssistancePOMDP, paper_task

    p, nxt = AssistancePOMDP(model, paper_task()).branches("bayes").successors(np.array([[0.4, 0.6]]), HIGH, ASK)
    assert p[0, RELY * 2 + RELIABLE] == 0.0 and p[0, RELY * 2 + FAULTY] == 0.0
    np.testing.assert_allclose(nxt.sum(axis=-1), 1.0)


def test_an_exact_finite_horizon_value_beyond_its_tree_budget_is_refused_up_front(monkeypatch):
    """solve-pomdp-file --horizon 8 on the exported paper problem expanded 2.5 M belief nodes
    (30 s); the tree is counted on the beliefs' supports first, and refused above the budget."""
    import trustseek.pomdp.belief as belief
    from pomdp_oracles import TIGER
    from trustseek.interop.files import read_pomdp

    flat = read_pomdp("tiger.pomdp", TIGER)
    tiger = flat.branch_model()  # 3 actions x 2 observations, every branch reachable
    assert [tiger.tree_size(flat.start, h) for h in (0, 1, 2, 3)] == [0, 1, 7, 43]
    assert tiger.finite_horizon_value(flat.start, 2) == pytest.approx(-1.95, abs=1e-12)
    monkeypatch.setattr(belief, "MAX_TREE_NODES", 42)
    with pytest.raises(belief.BeliefError, match="horizon 3: the exact value expands 43 belief nodes, more than 42"):
        tiger.finite_horizon_value(flat.start, 3)
