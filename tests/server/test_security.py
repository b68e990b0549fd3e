"""Access control: experimenter endpoints need the experimenter token; a session token reaches
its own session only."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from trustseek.server import create_app

TOKEN = "the-experimenter-token"
H = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    db = f"sqlite:///{tmp_path_factory.mktemp('sec') / 'sec.sqlite'}"
    with TestClient(create_app(db, token=TOKEN)) as c:
        st = c.post(
            "/api/studies",
            json={"name": "sec", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 3}}}]},
            headers=H,
        ).json()
        a, b = c.post(f"/api/studies/{st['id']}/sessions", json={"participants": ["a", "b"]}, headers=H).json()
        robot = c.post("/api/deploy/sessions", json={"policy": {"kind": "never-ask"}}, headers=H).json()
        yield c, st, a, b, robot


def experimenter_requests(st):
    sid = st["id"]
    return [
        ("get", "/api/studies", None),
        (
            "post",
            "/api/studies",
            {"name": "x", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 1}}}]},
        ),
        ("get", f"/api/studies/{sid}", None),
        ("post", f"/api/studies/{sid}/sessions", {"count": 1}),
        ("get", f"/api/studies/{sid}/dashboard", None),
        ("get", f"/api/studies/{sid}/export", None),
        ("get", f"/api/studies/{sid}/export?table=events", None),
        ("post", "/api/deploy/sessions", {"policy": {"kind": "never-ask"}}),
    ]


def call(c, method, path, body, headers):
    return c.request(method.upper(), path, json=body, headers=headers)


def test_experimenter_endpoints_reject_missing_or_wrong_tokens(env):
    c, st, a, _, robot = env
    n_studies = len(c.get("/api/studies", headers=H).json())
    for method, path, body in experimenter_requests(st):
        assert call(c, method, path, body, {}).status_code == 401, path
        assert call(c, method, path, body, {"Authorization": "Bearer wrong"}).status_code == 403, path
        assert call(c, method, path, body, {"Authorization": f"Bearer {TOKEN}x"}).status_code == 403, path
        assert call(c, method, path, body, {"Authorization": TOKEN}).status_code == 401, path  # not a bearer header
        # a participant's or a robot's token is not an experimenter token
        assert call(c, method, path, body, {"Authorization": f"Bearer {a['token']}"}).status_code == 403, path
        assert call(c, method, path, body, {"Authorization": f"Bearer {robot['token']}"}).status_code == 403, path
    assert len(c.get("/api/studies", headers=H).json()) == n_studies  # nothing was created


def test_a_participant_token_cannot_read_or_write_another_session(env):
    c, st, a, b, robot = env
    ha, hb = {"Authorization": f"Bearer {a['token']}"}, {"Authorization": f"Bearer {b['token']}"}
    assert c.post(f"/api/sessions/{b['session_id']}/consent", json={"agree": True}, headers=hb).status_code == 200
    b_state = c.get(f"/api/sessions/{b['session_id']}/state", headers=hb).json()
    other = b["session_id"]
    attempts = [
        ("get", f"/api/sessions/{other}/state", None),
        ("post", f"/api/sessions/{other}/consent", {"agree": True}),
        ("post", f"/api/sessions/{other}/trials", {"trial": 1, "submission_id": "evil", "human_action": "intervene"}),
        ("post", f"/api/sessions/{other}/reports", {"after_trial": 1, "value": 0}),
        ("post", f"/api/sessions/{other}/events", {"events": [{"type": "evil"}]}),
        ("get", f"/api/deploy/sessions/{robot['session_id']}", None),
        ("post", f"/api/deploy/sessions/{robot['session_id']}/decide", {"trial": 1, "complexity": "low"}),
        (
            "post",
            f"/api/deploy/sessions/{robot['session_id']}/observe",
            {"trial": 1, "human_action": "rely", "outcome": "success"},
        ),
    ]
    for method, path, body in attempts:
        assert call(c, method, path, body, ha).status_code == 403, path
        assert call(c, method, path, body, {}).status_code == 401, path
        assert call(c, method, path, body, {"Authorization": "Bearer not-a-token"}).status_code == 401, path
        assert call(c, method, path, body, H).status_code == 401, path  # the experimenter token is not a session token
    # B is untouched
    assert c.get(f"/api/sessions/{other}/state", headers=hb).json() == b_state
    ev = c.get(f"/api/studies/{st['id']}/export?table=events", headers=H).text
    assert "evil" not in ev
    # /api/session answers with the caller's own session only
    assert c.get("/api/session", headers=ha).json()["session_id"] == a["session_id"]
    assert c.get("/api/session", headers=hb).json()["session_id"] == b["session_id"]
    # a robot's token does not open a participant session and vice versa
    hr = {"Authorization": f"Bearer {robot['token']}"}
    assert c.get(f"/api/sessions/{a['session_id']}/state", headers=hr).status_code == 403
    assert c.get(f"/api/deploy/sessions/{robot['session_id']}", headers=hr).status_code == 200
    assert (
        c.post(f"/api/deploy/sessions/{a['session_id']}/decide", json={"trial": 1, "complexity": "low"}, headers=ha).status_code
        == 409
    )
    assert (
        c.post(
            f"/api/deploy/sessions/{robot['session_id']}/decide", json={"trial": 1, "complexity": "low"}, headers=hr
        ).status_code
        == 200
    )


def test_session_tokens_are_unguessable(env):
    c, st, a, b, robot = env
    made = c.post(f"/api/studies/{st['id']}/sessions", json={"count": 20}, headers=H).json()
    tokens = [m["token"] for m in made] + [a["token"], b["token"], robot["token"]]
    assert len(set(tokens)) == len(tokens)
    assert all(len(t) >= 43 for t in tokens)  # 32 random bytes, URL-safe base64
    assert all(m["link"].endswith("/s/" + m["token"]) for m in made)
    assert all(m["session_id"] not in m["token"] for m in made)
