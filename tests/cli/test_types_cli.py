"""Supervisor types on the command line and through the deploy API: solve for a mixture, a
returning person's warm start from their earlier trials, and simulating a population of types."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from cli_runner import run_cli
from trustseek.model import paper_conservative_mixture
from trustseek.policies import TypeAwarePolicy, load_policy
from trustseek.pomdp.supervisor_types import type_belief_from_log, warm_start_belief


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    out = tmp_path_factory.mktemp("types") / "policy.json"
    code, text = run_cli(["solve", "-m", "paper+conservative", "--max-seconds", "1", "--json", "--out", str(out)])
    assert code == 0, text
    return json.loads(text), out


def test_solve_on_a_mixture_gives_a_type_aware_policy(solved):
    summary, path = solved
    assert summary["solver"] == "point"
    assert summary["type_belief"] == pytest.approx({"paper": 0.7, "conservative": 0.3})
    lo, up = summary["value_bounds_at_initial_belief"]
    assert lo <= up
    policy = load_policy(path)
    assert isinstance(policy, TypeAwarePolicy) and policy.type_names == ("paper", "conservative")


def test_types_option_and_errors(tmp_path):
    mix = tmp_path / "mix.json"
    paper_conservative_mixture(0.5).save(mix)
    code, text = run_cli(["solve", "--types", str(mix), "--max-seconds", "0.5", "--json"])
    assert code == 0, text
    assert json.loads(text)["type_belief"]["conservative"] == pytest.approx(0.5)
    code, text = run_cli(["solve", "--history", str(mix)])
    assert code == 2 and "need supervisor types" in text
    code, text = run_cli(["solve", "-m", "paper+conservative", "--solver", "grid"])
    assert code == 2 and "point" in text  # the grid solver refuses four levels, naming an alternative


def test_simulate_a_population_of_types_and_warm_start_a_returning_person(solved, tmp_path):
    _, path = solved
    log = tmp_path / "trials.csv"
    code, text = run_cli(
        ["simulate", "-m", "paper+conservative", "--policy", str(path), "-n", "10", "--trials", "40", "--out", str(log)]
    )
    assert code == 0, text
    frame = pd.read_csv(log)
    assert frame["participant"].nunique() == 10
    # the person's type posterior from their trials, and the plan that starts from it
    post = type_belief_from_log(paper_conservative_mixture(), frame, participant="p003")
    out = tmp_path / "own.json"
    args = ["solve", "-m", "paper+conservative", "--history", str(log), "--participant", "p003", "--max-seconds", "0.5"]
    code, text = run_cli([*args, "--json", "--out", str(out)])
    assert code == 0, text
    assert list(json.loads(text)["type_belief"].values()) == pytest.approx(list(post))
    np.testing.assert_allclose(load_policy(out).model.initial, warm_start_belief(paper_conservative_mixture(), post))
    code, text = run_cli(["simulate", "-m", "paper+conservative", "--policy", "trust-aware"])
    assert code == 2 and "type-aware" in text


def test_simulate_takes_the_types_as_solve_does(solved, tmp_path):
    """``simulate --types`` is ``simulate --model`` with a mixture, as in ``solve``."""
    _, path = solved
    mix = tmp_path / "mix.json"
    paper_conservative_mixture().save(mix)
    common = ["--policy", str(path), "-n", "6", "--trials", "20", "--json"]
    code, by_types = run_cli(["simulate", "--types", str(mix), *common])
    assert code == 0, by_types
    code, by_model = run_cli(["simulate", "-m", "paper+conservative", *common])
    assert code == 0, by_model
    assert json.loads(by_types) == json.loads(by_model)
    code, text = run_cli(["simulate", "--types", str(mix), "-m", "paper", *common])
    assert code == 2 and "--model or with --types, not both" in text
    code, text = run_cli(["simulate", "--types", str(tmp_path / "missing.json"), *common])
    assert code == 2 and "missing.json" in text
    # one supervisor type is a trust model: the same simulation as the model itself
    plain = ["-n", "4", "--trials", "15", "--json"]
    code, one = run_cli(["simulate", "--types", "paper", *plain])
    assert code == 0, one
    code, model = run_cli(["simulate", "-m", "paper", *plain])
    assert code == 0, model
    assert json.loads(one) == json.loads(model)


def test_the_deploy_api_runs_a_type_aware_policy(solved, tmp_path):
    """The server's deploy sessions take the policy JSON as it is (its own product model)."""
    TestClient = pytest.importorskip("fastapi.testclient").TestClient
    from trustseek.client import Client
    from trustseek.policies import PolicyRunner
    from trustseek.server import create_app

    _, path = solved
    policy = load_policy(path)
    with TestClient(create_app(f"sqlite:///{tmp_path / 'db.sqlite'}", token="secret")) as http:
        robot = Client("http://test", "secret", http=http).open_deploy(model="paper", policy=json.loads(path.read_text()))
        runner = PolicyRunner(policy)
        events = [
            ("high", "intervene", None),
            ("low", "rely", "success"),
            ("high", "rely", "failure"),
            ("low", "rely", "success"),
        ]
        for cx, human, outcome in events:
            a = robot.decide(cx)
            assert a == runner.decide(cx)
            if a == "ask":
                human, outcome, e = None, None, "faulty" if cx == "low" else "reliable"
            else:
                e = "faulty" if human == "intervene" or outcome == "failure" else "reliable"
            robot.observe(human_action=human, outcome=outcome)
            runner.observe(cx, a, "intervene" if a == "ask" else human, e)
            # the API reports P(trust = high), summed over the types (not the last product level's)
            assert robot.belief == pytest.approx(policy.trust_belief(runner.belief)[-1], abs=1e-12)
            assert abs(robot.belief - runner.belief[-1]) > 1e-6
