"""The decision API's front (``server.deploy.http``) answers exactly as the FastAPI application
does: the same status and bytes for every request, successes and the session's refusals from
the front, malformed requests handed on; its held database connection recovers when it breaks."""

from __future__ import annotations

import asyncio
import json

import pytest
from fastapi import FastAPI
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from asgi_client import asgi_post
from server_checks import check_two_processes_serve_one_robot
from trustseek.server.app import ServerApp, create_app

TOKEN = "fast-path-experimenter-token"
POLICY = {"kind": "randomized", "p_ask": {"low": 0.3, "high": 0.6}}


def call(app: ServerApp, full: bool, path: str, body: bytes, token: str | None, headers: dict | None = None):
    """(status, content type, body) of one POST through the application's front (the lean path
    first) or, with ``full``, straight through the FastAPI application."""
    fields = {"content-type": "application/json", "content-length": str(len(body)), **(headers or {})}
    if token is not None:
        fields = {"authorization": f"Bearer {token}", **fields}

    async def front(scope, receive, send):
        if full:
            await FastAPI.__call__(app, {**scope, "app": app}, receive, send)
        else:
            await app(scope, receive, send)

    status, out_headers, out = asyncio.run(asgi_post(front, path, body, fields))
    assert b"server-timing" in out_headers
    return status, out_headers.get(b"content-type"), out


class Counting:
    """Counts the requests the lean path hands on to the full application."""

    def __init__(self, app: ServerApp):
        self.inner = app._front.app
        self.calls = 0
        app._front.app = self

    async def __call__(self, scope, receive, send):
        self.calls += 1
        await self.inner(scope, receive, send)


@pytest.fixture
def app(tmp_path):
    return create_app(f"sqlite:///{tmp_path / 'fast.sqlite'}", token=TOKEN)


def open_session(app: ServerApp, seed: int = 7, policy: dict | None = None) -> tuple[str, str]:
    body = json.dumps({"label": "robot", "policy": policy or POLICY, "seed": seed}).encode()
    status, _, out = call(app, True, "/api/deploy/sessions", body, TOKEN)
    assert status == 201, out
    info = json.loads(out)
    return info["session_id"], info["token"]


def post(app, full, sid, token, what, body, headers=None):
    raw = body if isinstance(body, bytes) else json.dumps(body).encode()
    return call(app, full, f"/api/deploy/sessions/{sid}/{what}", raw, token, headers)


@pytest.mark.parametrize("policy", [POLICY, {"kind": "trust-aware", "grid": 51}])
def test_successes_are_answered_by_the_lean_path_with_the_full_applications_bytes(app, policy):
    lean, full = open_session(app, policy=policy), open_session(app, policy=policy)
    counting = Counting(app)
    asked = {}
    for n in range(1, 13):
        d = asked[n] = {"trial": n, "complexity": "high" if n % 3 else "low"}
        a, b = post(app, False, *lean, "decide", d), post(app, True, *full, "decide", d)
        assert a == b and a[0] == 200
        assert post(app, False, *lean, "decide", d) == post(app, True, *full, "decide", d)  # repeated: the stored decision
        action = json.loads(a[2])["robot_action"]
        o = (
            {"trial": n}
            if action == "ask"
            else {"trial": n, "human_action": "rely", "outcome": "failure" if n % 4 else "success"}
        )
        a, b = post(app, False, *lean, "observe", o), post(app, True, *full, "observe", o)
        assert a == b and a[0] == 200 and json.loads(a[2])["duplicate"] is False
        a, b = post(app, False, *lean, "observe", o), post(app, True, *full, "observe", o)  # a retry: the stored trial
        assert a == b and json.loads(a[2])["duplicate"] is True
        # an earlier trial, asked again: the committed decision
        old = asked[max(1, n - 1)]
        assert post(app, False, *lean, "decide", old) == post(app, True, *full, "decide", old)
    assert counting.calls == 0


def test_refusals_are_answered_by_the_front_and_malformed_requests_by_fastapi(app):
    """The session's refusals (400, 404, 409) come from the one answer of the request, through
    the front as through FastAPI; a request the schema refuses, or with another token, is handed
    to FastAPI (401, 403, 413, 422)."""
    sid, token = open_session(app)
    other_sid, other_token = open_session(app, seed=8)
    counting = Counting(app)
    answered, handed = True, False
    cases = [
        ("decide", {"trial": 1.0, "complexity": "low"}, token, None, handed),
        ("decide", {"trial": True, "complexity": "low"}, token, None, handed),
        ("decide", {"trial": 0, "complexity": "low"}, token, None, handed),
        ("decide", {"trial": 1, "complexity": "low", "extra": 1}, token, None, handed),
        ("decide", {"trial": 1, "complexity": ""}, token, None, handed),
        ("decide", {"trial": 1, "complexity": "medium"}, token, None, answered),  # 400: not a complexity of the task
        ("decide", {"trial": 2, "complexity": "low"}, token, None, answered),  # 409: not the next trial
        ("decide", {"trial": 1}, token, None, answered),  # 400: no complexity
        ("decide", {"trial": 1, "remaining": {"low": 1}}, token, None, answered),  # 400: not a schedule policy
        ("decide", {"trial": 1, "remaining": {"low": True}}, token, None, handed),  # 422: not a count
        ("decide", {"trial": 1, "complexity": "low"}, other_token, None, handed),  # 403: another session's token
        ("decide", {"trial": 1, "complexity": "low"}, TOKEN, None, handed),  # 401: the experimenter's token
        ("decide", {"trial": 1, "complexity": "low"}, "no-such-token", None, handed),  # 401
        ("decide", {"trial": 1, "complexity": "low"}, None, None, handed),  # 401: no token
        ("decide", {"trial": 1, "complexity": "low"}, token, {"content-length": str(10**7)}, handed),  # 413
        ("decide", {"trial": 1, "complexity": "low"}, token, {"content-type": "text/plain"}, handed),
        ("decide", b'{"trial": 1, "complexity": "lo', token, None, handed),  # 422: not JSON
        ("decide", b"\xff\xfe\x00", token, None, handed),
        ("decide", [1, 2], token, None, handed),
        ("observe", {"trial": 1, "human_action": "rely", "outcome": "success"}, token, None, answered),  # 409: no decision
        ("observe", {"trial": 1, "human_action": "maybe"}, token, None, handed),
        ("observe", {"trial": 1, "outcome": 3}, token, None, handed),
    ]
    for what, body, tok, headers, by_front in cases:
        before = counting.calls
        a = post(app, False, sid, tok, what, body, headers)
        b = post(app, True, sid, tok, what, body, headers)
        assert a == b, (what, body)
        assert a[0] >= 400, (what, body, a)
        assert counting.calls == before + (0 if by_front else 1), (what, body)
    # nothing was written: the session's first trial is still to be decided
    assert post(app, False, sid, token, "decide", {"trial": 1, "complexity": "low"})[0] == 200
    assert other_sid != sid


values = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-2, 12),
    st.floats(allow_nan=False, allow_infinity=False, width=16),
    st.sampled_from(["low", "high", "", "medium", "rely", "intervene", "success", "failure", "teleoperated", "collision"]),
    st.dictionaries(st.sampled_from(["low", "high"]), st.integers(-1, 3), max_size=2),
)
bodies = st.dictionaries(
    st.sampled_from(["trial", "complexity", "human_action", "outcome", "remaining", "visible", "x"]), values, max_size=4
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.sampled_from(["decide", "observe"]), bodies), min_size=1, max_size=8))
def test_any_request_sequence_gets_the_full_applications_answers(app, requests):
    """Two sessions with the same seed, one through the front and one through the full
    application, given the same requests, answer alike at every step."""
    lean, full = open_session(app, seed=3), open_session(app, seed=3)
    for what, body in requests:
        assert post(app, False, *lean, what, body) == post(app, True, *full, what, body), (what, body)


def test_a_broken_connection_is_replaced(app):
    sid, token = open_session(app)
    assert post(app, False, sid, token, "decide", {"trial": 1, "complexity": "low"})[0] == 200
    store = app.state.deploy_store
    store._fairy.driver_connection.close()  # the held connection breaks
    status, _, out = post(app, False, sid, token, "observe", {"trial": 1, "human_action": "intervene"})
    assert status == 200, out
    assert json.loads(out)["trial"]["trial"] == 1
    assert post(app, False, sid, token, "decide", {"trial": 2, "complexity": "high"})[0] == 200


def test_two_applications_on_one_database_answer_as_one(tmp_path):
    check_two_processes_serve_one_robot(f"sqlite:///{tmp_path / 'two.sqlite'}", TOKEN)


def test_the_decision_store_closes_its_connections_when_the_server_stops(tmp_path, monkeypatch):
    """Before, the decision API's connections stayed open after shutdown (PostgreSQL kept their backends)."""
    from fastapi.testclient import TestClient

    from trustseek.server.deploy.store import DeployStore

    closed: list[DeployStore] = []
    real = DeployStore.close
    monkeypatch.setattr(DeployStore, "close", lambda self: (closed.append(self), real(self))[1])
    app = create_app(f"sqlite:///{tmp_path / 'stop.sqlite'}", token=TOKEN)
    with TestClient(app):
        open_session(app)
        assert not closed
    assert closed == [app.state.deploy_store]
