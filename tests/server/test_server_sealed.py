"""Sealed outcomes: nothing the participant's page receives predicts an outcome before it is
shown.  The predictors below are what a participant's script could run: the recovery of the
session seed from the scene seed (the attack on the earlier scheme, which drew outcomes from
``default_rng([seed, n, 1])`` and sent ``scene_seed = (seed * 1000003 + n) mod 2**31``), and a
logistic regression on every number the page receives, fitted on some trials and scored on
held-out ones.  Each is shown to succeed on a session served the earlier way (a session without
a secret), so the test can fail."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient
from scipy.optimize import minimize
from scipy.stats import binomtest, fisher_exact
from sqlalchemy import create_engine, text

from trustseek.model.presets import paper_task
from trustseek.server import create_app

TOKEN = "experimenter-secret"
H = {"Authorization": f"Bearer {TOKEN}"}
TRIALS = 120
P_HIGH = float(paper_task().success[1])  # autonomous success in high complexity


@pytest.fixture
def app_and_url(tmp_path):
    url = f"sqlite:///{tmp_path / 'sealed.sqlite'}"
    with TestClient(create_app(url, token=TOKEN)) as c:
        yield c, url


def walk_keys(value, out: set[str]) -> set[str]:
    if isinstance(value, dict):
        for k, v in value.items():
            out.add(k)
            walk_keys(v, out)
    elif isinstance(value, list):
        for v in value:
            walk_keys(v, out)
    return out


def run_session(client, study_id: str, legacy_url: str | None = None) -> tuple[list[dict], list[str], list]:
    """A participant who always relies: every served trial as the page saw it before its outcome,
    the outcomes, and every JSON body the participant's endpoints returned.  With ``legacy_url``
    the session's secret is removed first, so it is served the earlier way."""
    (info,) = client.post(f"/api/studies/{study_id}/sessions", json={"count": 1}, headers=H).json()
    sid, ph = info["session_id"], {"Authorization": f"Bearer {info['token']}"}
    if legacy_url is not None:
        with create_engine(legacy_url).begin() as conn:
            conn.execute(text("update sessions set secret = null where id = :i"), {"i": sid})
    bodies = [client.get("/api/session", headers=ph).json()]
    state = client.post(f"/api/sessions/{sid}/consent", json={"agree": True}, headers=ph).json()
    bodies.append(state)
    served, outcomes = [], []
    while state["current"] is not None:
        cur = state["current"]
        served.append(dict(cur))
        body = {"trial": cur["trial"], "submission_id": f"s{cur['trial']}", "human_action": "rely"}
        res = client.post(f"/api/sessions/{sid}/trials", json=body, headers=ph).json()
        bodies.append(res)
        outcomes.append(res["trial"]["outcome"])
        state = res["state"]
    return served, outcomes, bodies


def seed_recovery(served: list[dict]) -> np.ndarray:
    """Predicted success per trial: the session seed recovered from the scene seed, the outcome
    drawn as the earlier scheme drew it."""
    inv = pow(1000003, -1, 2**31)
    out = []
    for cur in served:
        n = cur["trial"]
        seed = ((cur["scene_seed"] - n) * inv) % 2**31
        out.append(np.random.default_rng([seed, n, 1]).random() < P_HIGH)
    return np.array(out)


def features(served: list[dict]) -> np.ndarray:
    """Every number the page has about a trial before its outcome: the trial number and the 31
    bits of the scene seed (the complexity and the action are the same in every trial here)."""
    rows = []
    for cur in served:
        bits = [(cur["scene_seed"] >> k) & 1 for k in range(31)]
        rows.append([1.0, cur["trial"] / TRIALS, *bits])
    return np.array(rows, dtype=float)


def logistic_heldout(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A ridge logistic regression fitted on the first half, predictions on the second half."""
    half = len(y) // 2

    def loss(w):
        z = x[:half] @ w
        return np.sum(np.logaddexp(0, z) - y[:half] * z) + 0.5 * w @ w

    w = minimize(loss, np.zeros(x.shape[1]), method="L-BFGS-B").x
    return (x[half:] @ w) > 0


def independence_p(predicted: np.ndarray, actual: np.ndarray) -> float:
    """One-sided p-value that predictions and outcomes agree more than by chance."""
    table = [
        [np.sum(predicted & actual), np.sum(predicted & ~actual)],
        [np.sum(~predicted & actual), np.sum(~predicted & ~actual)],
    ]
    return float(fisher_exact(table, alternative="greater").pvalue)


def test_participant_side_predictors_are_at_chance(app_and_url):
    client, url = app_and_url
    study = {
        "name": "sealed",
        "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"high": TRIALS}}}],
    }
    st = client.post("/api/studies", json=study, headers=H).json()

    # the earlier scheme: both predictors succeed (so this test can fail)
    served, outcomes, _ = run_session(client, st["id"], legacy_url=url)
    actual = np.array([o == "success" for o in outcomes])
    assert (seed_recovery(served) == actual).all()

    # sealed sessions: everything the page received, and no predictor beats chance
    served, outcomes, bodies = [], [], []
    for _ in range(2):
        s, o, b = run_session(client, st["id"])
        served += s
        outcomes += o
        bodies += b
    actual = np.array([o == "success" for o in outcomes])
    assert 0.6 < actual.mean() < 0.95  # the task's success probability in high complexity
    keys = walk_keys(bodies, set())
    assert not keys & {"belief", "belief_after", "experience", "seed", "secret"}, keys
    assert independence_p(seed_recovery(served), actual) > 1e-4
    pred = logistic_heldout(features(served), actual.astype(float))
    held = actual[len(actual) // 2 :]
    # the held-out accuracy is no better than the base rate (a binomial test)
    base = max(held.mean(), 1 - held.mean())
    assert binomtest(int(np.sum(pred == held)), len(held), base, alternative="greater").pvalue > 1e-4


def test_logistic_predictor_learns_a_leaky_feature():
    """The logistic predictor finds an outcome that the scene seed gives away (as a page would
    if the scene seed were drawn with the outcome): it is a real predictor, not a constant."""
    rng = np.random.default_rng(0)
    actual = rng.random(2 * TRIALS) < P_HIGH
    served = [{"trial": n + 1, "scene_seed": int(rng.integers(0, 2**30)) * 2 + int(a)} for n, a in enumerate(actual)]
    pred = logistic_heldout(features(served), actual.astype(float))
    held = actual[TRIALS:]
    base = max(held.mean(), 1 - held.mean())
    assert binomtest(int(np.sum(pred == held)), len(held), base, alternative="greater").pvalue < 1e-4


def test_a_session_is_reproducible_from_its_record(app_and_url):
    """The experimenter's sessions export holds the seed and the secret; with them the outcomes
    and scene seeds are recomputed exactly."""
    import io

    import pandas as pd

    from trustseek.server.sessions import sealed

    client, _ = app_and_url
    study = {"name": "rep", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"high": 20}}}]}
    st = client.post("/api/studies", json=study, headers=H).json()
    served, outcomes, _ = run_session(client, st["id"])
    rec = pd.read_csv(io.BytesIO(client.get(f"/api/studies/{st['id']}/export", params={"table": "sessions"}, headers=H).content))
    secret = rec["secret"].iloc[0]
    for cur, o in zip(served, outcomes, strict=True):
        n = cur["trial"]
        assert cur["scene_seed"] == sealed(secret, "scene", n) % 2**31
        r = np.random.default_rng(sealed(secret, "outcome", n)).random(2)
        assert (o == "success") == (r[0] < P_HIGH)
