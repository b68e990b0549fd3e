"""Hostile request bodies get a 4xx, never a 5xx, on SQLite and on PostgreSQL alike, over real
HTTP: bodies nested 100,000 deep (to the lean path of the decision API and to the full
application), a task whose rewards overflow, a NUL character in any JSON string (PostgreSQL's
text cannot hold one), and any JSON value or bytes hypothesis makes up (valid bodies with any text
in their strings or any value in their fields; the property finds the NUL of PostgreSQL without
the body guard); schemathesis over every operation on PostgreSQL (``test_server_schema`` runs
its full checks on SQLite)."""

from __future__ import annotations

import json

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from schemathesis.checks import not_a_server_error

from server_checks import api_ids, case_headers
from trustseek import paper_task
from trustseek.testing.servers import TemporaryPostgres, ThreadServer, postgres_binaries

TOKEN = "hostile-experimenter-token"
H = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def http(request, tmp_path_factory):
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path_factory.mktemp('hostile') / 'hostile.sqlite'}"
        cluster = None
    else:
        if postgres_binaries() is None:
            pytest.skip("PostgreSQL server binaries (initdb, pg_ctl) not found")
        cluster = TemporaryPostgres()
        url = cluster.start()
    try:
        with ThreadServer(url, TOKEN) as base, httpx.Client(base_url=base, timeout=60) as c:
            yield c
    finally:
        if cluster is not None:
            cluster.stop()


def post(http, path: str, body: str | bytes, headers: dict[str, str]) -> httpx.Response:
    raw = body.encode() if isinstance(body, str) else body
    return http.post(path, content=raw, headers={**headers, "Content-Type": "application/json"})


def robot(http) -> tuple[str, dict[str, str]]:
    r = post(http, "/api/deploy/sessions", json.dumps({"policy": {"kind": "trust-aware"}}), H)
    assert r.status_code == 201, r.text
    d = r.json()
    return f"/api/deploy/sessions/{d['session_id']}", {"Authorization": f"Bearer {d['token']}"}


def participant(http) -> tuple[str, dict[str, str]]:
    study = {"name": "hostile", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 4}}}]}
    r = post(http, "/api/studies", json.dumps(study), H)
    assert r.status_code == 201, r.text
    s = post(http, f"/api/studies/{r.json()['id']}/sessions", '{"count": 1}', H).json()[0]
    ph = {"Authorization": f"Bearer {s['token']}"}
    base = f"/api/sessions/{s['session_id']}"
    assert post(http, f"{base}/consent", '{"agree": true}', ph).status_code == 200
    return base, ph


def nested(depth: int) -> str:
    return '{"trial": 1, "complexity": ' + "[" * depth + "]" * depth + "}"


@pytest.mark.parametrize("depth", [100_000, 5_000, 900, 400])
def test_deeply_nested_bodies_are_a_422(http, depth):
    """A body nested 100,000 deep was a 500 from the lean path (RecursionError escaped it); a
    few hundred deep, one the JSON parser takes, the echo of the refused input failed instead."""
    base, rh = robot(http)
    pbase, ph = participant(http)
    for path, headers in (
        (f"{base}/decide", rh),
        (f"{base}/observe", rh),
        (f"{pbase}/trials", ph),
        (f"{pbase}/events", ph),
        ("/api/studies", H),
        ("/api/deploy/sessions", H),
    ):
        for body in (nested(depth), "[" * depth + "]" * depth):
            r = post(http, path, body, headers)
            assert r.status_code == 422, (path, r.status_code, r.text[:200])
            assert "nested" in r.json()["detail"][0]["msg"]
    # the session still works
    assert post(http, f"{base}/decide", '{"trial": 1, "complexity": "high"}', rh).status_code == 200


def test_a_task_with_rewards_that_overflow_is_refused_or_works(http):
    """Rewards of +-1e308 made the trust-aware policy's values infinite: a 500 when the session
    was opened.  Now a 400 naming the rewards, for every policy; a session's score that could
    overflow is refused the same way."""
    task = paper_task().to_dict()
    task["rewards"] = {"autonomous_success": 1e308, "ask": 1.0, "intervene": 0.0, "autonomous_failure": -1e308}
    for kind in ("trust-aware", "never-ask", "trust-agnostic", "always-ask"):
        r = post(http, "/api/deploy/sessions", json.dumps({"task": task, "policy": {"kind": kind}}), H)
        assert r.status_code == 400, (kind, r.text)
        assert "rewards" in json.dumps(r.json()["detail"])


@pytest.mark.parametrize("where", ["study name", "participant id", "deploy label", "event type", "complexity", "path"])
def test_a_nul_character_in_a_string_is_a_400(http, where):
    """PostgreSQL's text cannot hold NUL (a 500 there, stored on SQLite): refused on both."""
    nul = "a\x00b"  # json.dumps writes it as the escape \u0000
    if where == "study name":
        study = {"name": nul, "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 4}}}]}
        r = post(http, "/api/studies", json.dumps(study), H)
    elif where == "participant id":
        study = {"name": "n", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 4}}}]}
        made = post(http, "/api/studies", json.dumps(study), H)
        assert made.status_code == 201, made.text
        r = post(http, f"/api/studies/{made.json()['id']}/sessions", json.dumps({"participants": [nul]}), H)
    elif where == "deploy label":
        r = post(http, "/api/deploy/sessions", json.dumps({"label": nul, "policy": {"kind": "never-ask"}}), H)
    elif where == "event type":
        base, ph = participant(http)
        r = post(http, f"{base}/events", json.dumps({"events": [{"type": nul}], "batch": "b1"}), ph)
    elif where == "complexity":
        base, rh = robot(http)
        r = post(http, f"{base}/decide", json.dumps({"trial": 1, "complexity": nul}), rh)
    else:
        r = http.get("/api/studies/a%00b", headers=H)
    assert r.status_code == 400, r.text
    assert "NUL" in json.dumps(r.json()["detail"])
    # an escaped backslash before u0000 is no NUL character
    r = post(http, "/api/deploy/sessions", '{"label": "a\\\\u0000b", "policy": {"kind": "never-ask"}}', H)
    assert r.status_code == 201, r.text


texts = st.sampled_from(["low", "high", "rely", "success", "a\x00b", "\x00", "x\x00", "caf\u00e9\x00"]) | st.text(max_size=12)
json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | texts,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(texts, inner, max_size=4),
    max_leaves=12,
)
#: a valid body of each request, and the paths of its strings: a generated body replaces a string
#: with any text, or replaces or adds fields with any JSON value
VALID = {
    "decide": {"trial": 1, "complexity": "high"},
    "observe": {"trial": 1, "human_action": "rely", "outcome": "success"},
    "events": {"events": [{"type": "x"}]},
    "trials": {"trial": 1, "submission_id": "s1", "human_action": "rely"},
    "studies": {"name": "n", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 2}}}]},
    "deploy": {"label": "r", "policy": {"kind": "never-ask"}},
}
STRINGS = {
    "decide": [("complexity",)],
    "observe": [("human_action",), ("outcome",)],
    "events": [("events", 0, "type")],
    "trials": [("submission_id",), ("human_action",)],
    "studies": [("name",), ("blocks", 0, "policy", "kind")],
    "deploy": [("label",), ("policy", "kind")],
}
FIELDS = sorted({k for body in VALID.values() for k in body} | {"remaining", "visible", "participants", "task", "model"})


@st.composite
def bodies(draw, which: str) -> bytes:
    kind = draw(st.sampled_from(["string", "fields", "value", "bytes"]))
    if kind == "bytes":
        return draw(st.binary(max_size=64))
    if kind == "value":
        return json.dumps(draw(json_values)).encode()
    body = json.loads(json.dumps(VALID[which]))
    if kind == "string":
        *head, last = draw(st.sampled_from(STRINGS[which]))
        leaf = body
        for k in head:
            leaf = leaf[k]
        leaf[last] = draw(texts)
    else:
        keys = st.sampled_from(sorted(body)) | st.sampled_from(FIELDS)
        body.update(draw(st.dictionaries(keys, texts | json_values, min_size=1, max_size=3)))
    return json.dumps(body).encode()


@settings(max_examples=200, deadline=None, suppress_health_check=list(HealthCheck), database=None)
@given(data=st.data(), which=st.sampled_from(sorted(VALID)))
def test_no_request_body_gets_a_5xx(http, data, which):
    if not hasattr(http, "_hostile_sessions"):
        http._hostile_sessions = (robot(http), participant(http))
    (rbase, rh), (pbase, ph) = http._hostile_sessions
    path, headers = {
        "decide": (f"{rbase}/decide", rh),
        "observe": (f"{rbase}/observe", rh),
        "events": (f"{pbase}/events", ph),
        "trials": (f"{pbase}/trials", ph),
        "studies": ("/api/studies", H),
        "deploy": ("/api/deploy/sessions", H),
    }[which]
    body = data.draw(bodies(which))
    r = post(http, path, body, headers)
    assert r.status_code < 500, (path, body, r.status_code, r.text[:300])


# --------------------------------------------------------------------------- schemathesis on PostgreSQL
# (tests/server/test_server_schema.py runs every check on SQLite; here, no 5xx on PostgreSQL, whose
# text cannot hold NUL and whose driver is another)


@pytest.fixture(scope="module")
def pg_app():
    from trustseek.server.app import create_app

    if postgres_binaries() is None:
        pytest.skip("PostgreSQL server binaries (initdb, pg_ctl) not found")
    cluster = TemporaryPostgres()
    app = create_app(cluster.start(), token=TOKEN)
    try:
        yield app
    finally:
        app.state.deploy_store.close()
        app.state.engine.dispose()
        cluster.stop()


@pytest.fixture(scope="module")
def pg_ids(pg_app) -> dict[str, str]:
    """A study with a participant session, and a deploy session on PostgreSQL."""
    from fastapi.testclient import TestClient

    return api_ids(TestClient(pg_app), TOKEN)


def test_no_operation_gets_a_5xx_on_postgresql(pg_app, pg_ids):
    """Every operation of the OpenAPI description, with examples schemathesis makes from it."""
    schema = schemathesis.openapi.from_asgi("/openapi.json", pg_app)
    for result in schema.get_all_operations():
        operation = result.ok()

        @settings(max_examples=10, deadline=None, suppress_health_check=list(HealthCheck), database=None)
        @given(case=operation.as_strategy())
        def no_5xx(case):
            case.call_and_validate(headers=case_headers(case, pg_ids, TOKEN), checks=[not_a_server_error])

        no_5xx()
