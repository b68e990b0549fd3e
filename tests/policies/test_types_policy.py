"""The type-aware policy runs wherever a policy runs: its JSON kind, PolicyRunner, the simulator
on a population of types, and a returning person's warm start."""

from __future__ import annotations

import numpy as np
import pytest

from trustseek.model import paper_conservative_mixture, paper_task
from trustseek.policies import PolicyRunner, TypeAwarePolicy
from trustseek.pomdp.supervisor_types import product_model, type_belief_from_log, warm_start_belief
from trustseek.simulation import Supervisors, simulate
from trustseek.solvers.type_aware import solve_type_aware
from trustseek.vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS


@pytest.fixture(scope="module")
def mixture():
    return paper_conservative_mixture(0.3)


@pytest.fixture(scope="module")
def policy(mixture):
    return solve_type_aware(mixture, paper_task(), max_seconds=1.0)


def test_the_solve_returns_a_type_aware_policy_with_its_bounds(policy, mixture):
    assert isinstance(policy, TypeAwarePolicy)
    assert policy.kind == "type-aware"
    assert policy.type_names == ("paper", "conservative")
    assert policy.model.trust_levels == product_model(mixture).trust_levels
    lo, up = policy.info["value_bounds_at_initial_belief"]
    assert lo <= up
    assert (policy.value_vectors @ product_model(mixture).initial).max() == pytest.approx(lo)


def test_the_file_holds_the_mixture_not_the_product_model(policy):
    d = policy.to_dict()
    assert d["kind"] == "type-aware" and "model" not in d and d["mixture"]["format"] == "trustseek.mixture/1"


def test_the_simulator_and_the_runner_agree_on_a_population_of_types(policy, mixture):
    """Each participant behaves as their own type; the robot's belief is over (type, trust)."""
    task = paper_task()
    sup = Supervisors.from_mixture(mixture, 10, rng=1)
    sim = simulate(sup, task, policy, trials=25, seed=4)
    a = sim.arrays
    for i in range(sim.n):
        runner = PolicyRunner(policy)
        for t in range(a["action"].shape[1]):
            c = int(a["complexity"][i, t])
            assert runner.belief[-1] == pytest.approx(a["belief"][i, t], abs=1e-9)
            assert runner.decide(c) == ACTIONS[a["action"][i, t]], (i, t)
            runner.observe(c, ACTIONS[a["action"][i, t]], HUMAN_ACTIONS[a["human"][i, t]], EXPERIENCES[a["experience"][i, t]])
    assert sim.trust_levels == ("low", "high")  # the participants' own trust, not the product's


def test_a_returning_person_starts_from_their_type_posterior(policy, mixture):
    task = paper_task()
    sup = Supervisors.from_models([mixture.models[1]], 1)
    log = simulate(sup, task, policy, trials=30, seed=9).trials()
    post = type_belief_from_log(mixture, log)
    runner = PolicyRunner(policy, belief=policy.initial_belief(post))
    np.testing.assert_allclose(policy.type_belief(runner.belief), post)
    np.testing.assert_allclose(runner.belief, warm_start_belief(mixture, post))
    # the person's own policy: the same solve from their type belief
    own = solve_type_aware(mixture, task, max_seconds=1.0, type_belief=post)
    np.testing.assert_allclose(own.model.initial, warm_start_belief(mixture, post))
    assert own.info["type_weights"] == pytest.approx(list(post / post.sum()))
