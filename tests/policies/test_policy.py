"""Policies: decisions, the trust-agnostic computation, JSON, and the runner."""

import numpy as np
import pandas as pd
import pytest

from trustseek import (
    ComplexityPolicy,
    PolicyRunner,
    TrustAwarePolicy,
    always_ask,
    load_policy,
    never_ask,
    randomized,
    solve,
    trust_agnostic,
)
from trustseek.model.jsonfile import ModelError
from trustseek.solvers.agnostic import agnostic_from_intervention_rates, trust_agnostic_from_data
from trustseek.vocab import ASK, AUTONOMOUS


@pytest.fixture(scope="module")
def aware():
    from trustseek import paper_model, paper_task

    return solve(paper_model(), paper_task(), grid=1001)


def test_trust_aware_actions_follow_threshold(aware):
    th = aware.thresholds()["high"]
    b = np.array([0.0, 0.2, th - 0.01, th + 0.01, 0.9, 1.0])
    beliefs = np.stack([1 - b, b], axis=1)
    assert aware.actions(beliefs, np.ones(6, dtype=int)).tolist() == [ASK] * 3 + [AUTONOMOUS] * 3
    assert aware.actions(beliefs, np.zeros(6, dtype=int)).tolist() == [AUTONOMOUS] * 6
    assert aware.action(0.5, "high") == ASK
    assert aware.action(0.95, "high") == AUTONOMOUS
    with pytest.raises(KeyError, match="unknown complexity"):
        aware.action(0.5, "medium")


def test_agnostic_rule_by_hand(task):
    # autonomous in high: (1 - p) * (0.83 * 2 - 0.17 * 3) = (1 - p) * 1.15 vs ask = 1
    pol = agnostic_from_intervention_rates(task, [0.02, 0.2])
    assert pol.p_ask.tolist() == [0.0, 1.0]
    pol = agnostic_from_intervention_rates(task, [0.02, 0.1])
    assert pol.p_ask.tolist() == [0.0, 0.0]
    assert pol.info["expected_reward"]["high"]["autonomous"] == pytest.approx(0.9 * 1.15)


def test_agnostic_from_paper_model_matches_section_6a(model, task):
    pol = trust_agnostic(model, task)
    assert pol.kind == "trust-agnostic"
    assert pol.p_ask.tolist() == [0.0, 1.0]  # never ask in low, always ask in high


def test_agnostic_from_data(task):
    rows = []
    for i in range(100):
        rows.append(("p1", i + 1, "high", "autonomous", "intervene" if i < 30 else "rely", "faulty"))
        rows.append(("p1", i + 101, "low", "autonomous", "rely", "reliable"))
    rows.append(("p1", 201, "high", "ask", "intervene", "reliable"))
    df = pd.DataFrame(rows, columns=["participant", "trial", "complexity", "robot_action", "human_action", "experience"])
    pol = trust_agnostic_from_data(df, task)
    assert pol.info["p_intervene"] == {"low": 0.0, "high": 0.3}
    assert pol.p_ask.tolist() == [0.0, 1.0]


def test_randomized_frequencies(rng):
    pol = randomized()
    n = 200_000
    c = rng.integers(0, 2, n)
    a = pol.actions(np.full((n, 2), 0.5), c, rng)
    assert a[c == 0].mean() == pytest.approx(0.10, abs=0.004)
    assert a[c == 1].mean() == pytest.approx(0.40, abs=0.005)


def test_fixed_policies():
    assert always_ask().actions(None, np.array([0, 1])).tolist() == [1, 1]
    assert never_ask().actions(None, np.array([0, 1])).tolist() == [0, 0]
    with pytest.raises(ModelError, match=r"p_ask must lie in \[0, 1\]"):
        ComplexityPolicy("randomized", ["low", "high"], [0.1, 1.4])


def test_bad_policy_file(tmp_path):
    (tmp_path / "p.json").write_text('{"format": "trustseek.policy/1", "kind": "sometimes", "complexities": ["low", "high"]}')
    with pytest.raises(ModelError, match="unknown policy kind 'sometimes'"):
        load_policy(tmp_path / "p.json")


def test_runner_tracks_belief(aware):
    run = PolicyRunner(aware, rng=np.random.default_rng(0))
    assert run.belief.tolist() == [0.0, 1.0]
    assert run.decide("high") == "autonomous"
    # a failure in high complexity drops trust to low (Fig. 6b): the robot then asks
    run.observe("high", "autonomous", "rely", "faulty")
    assert run.belief[1] == pytest.approx(0.0)
    assert run.decide("high") == "ask"
    assert run.decide("low") == "autonomous"
    # asking in high complexity repairs trust w.p. 0.44
    run.observe("high", "ask", "intervene", "reliable")
    assert run.belief[1] == pytest.approx(0.44)
    with pytest.raises(ValueError, match="human action"):
        run.observe("high", "ask", "maybe", "reliable")
    assert run.trial == 2


def test_non_threshold_policy_writes_valid_json(tmp_path, aware):
    # an ask region that is not [0, θ): asks only for beliefs in the middle
    q = aware.q.copy()
    adv = np.zeros(len(aware.grid))
    adv[(aware.grid > 0.3) & (aware.grid < 0.6)] = 1.0
    q[:, 1, ASK] = q[:, 1, AUTONOMOUS] + adv - 0.5
    odd = TrustAwarePolicy(aware.grid, q, aware.model, aware.complexities, aware.belief_update)
    assert np.isnan(odd.thresholds()["high"])
    assert [round(x, 2) for x in odd.ask_intervals()["high"][0]] == [0.3, 0.6]
    odd.save(tmp_path / "odd.json")
    import json

    d = json.loads((tmp_path / "odd.json").read_text())
    assert d["thresholds"]["high"] is None
    np.testing.assert_allclose(load_policy(tmp_path / "odd.json").q, q, atol=1e-9)


def test_ask_regions_of_complexity_policies(model, task):
    """A policy that ignores the belief asks on all of [0, 1] or nowhere; its bounds for the
    simulator follow."""
    from trustseek.policies import PolicyError, ask_bounds

    agn = trust_agnostic(model, task)  # never in low, always in high
    assert agn.ask_intervals() == {"low": [], "high": [(0.0, 1.0)]}
    assert agn.thresholds() == {"low": None, "high": 1.0}
    assert ask_bounds(agn).tolist() == [-np.inf, np.inf]
    with pytest.raises(PolicyError, match="no Q-function"):
        agn.q_values(0.5)


def test_tabulated_q_keeps_the_decisions(aware):
    from trustseek.policies import PolicyError

    table = TrustAwarePolicy.tabulate(aware, points=len(aware.grid))
    np.testing.assert_allclose(table.q, aware.q, atol=1e-9)
    assert table.thresholds()["high"] == pytest.approx(aware.thresholds()["high"], abs=1e-9)
    with pytest.raises(PolicyError, match="no Q-function"):
        TrustAwarePolicy.tabulate(never_ask())
