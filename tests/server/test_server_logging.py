"""The experiment server's log: start-up, studies, sessions and refused or failed requests, with
their context and without any token."""

from __future__ import annotations

import logging

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from trustseek.server import create_app
from trustseek.server.middleware import RequestLog, request_context

TOKEN = "experimenter-secret"
H = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture
def caplog_server(caplog):
    caplog.set_level(logging.INFO, logger="trustseek")
    return caplog


def messages(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name.startswith("trustseek.server")]


def test_a_session_from_start_to_finish_is_logged(tmp_path, caplog_server):
    url = f"sqlite:///{tmp_path / 'study.sqlite'}"
    with TestClient(create_app(url, token=TOKEN)) as client:
        body = {"name": "pilot", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 1, "high": 1}}}]}
        study = client.post("/api/studies", json=body, headers=H).json()
        s = client.post(f"/api/studies/{study['id']}/sessions", json={"count": 1}, headers=H).json()[0]
        ph = {"Authorization": f"Bearer {s['token']}"}
        client.post(f"/api/sessions/{s['session_id']}/consent", json={"agree": True}, headers=ph)
        for n in (1, 2):
            r = client.post(
                f"/api/sessions/{s['session_id']}/trials",
                json={"trial": n, "submission_id": f"s{n}", "human_action": "rely"},
                headers=ph,
            )
            assert r.status_code == 200, r.text
    log = messages(caplog_server)
    assert any(m.startswith("trustseek ") and "experiment server: database sqlite:///" in m for m in log)
    assert f"study {study['id']} created: 'pilot', 1 blocks" in log
    assert f"study {study['id']}: 1 participant sessions created" in log
    assert f"session {s['session_id']} of study {study['id']} started (consent given)" in log
    assert any(m.startswith(f"session {s['session_id']} of study {study['id']} finished: 2 trials") for m in log)
    assert not any(s["token"] in m or TOKEN in m for m in log)


def test_refused_requests_are_logged_with_their_route_and_no_token(tmp_path, caplog_server):
    with TestClient(create_app(f"sqlite:///{tmp_path / 'study.sqlite'}", token=TOKEN)) as client:
        assert client.get("/api/studies/nope", headers=H).status_code == 404
        assert client.get("/api/sessions/abc/state", headers={"Authorization": "Bearer not-a-token"}).status_code == 401
    refused = [r for r in caplog_server.records if r.name == "trustseek.server.middleware"]
    assert [r.getMessage() for r in refused] == [
        "GET /api/studies/{study_id} study_id=nope -> 404",
        "GET /api/sessions/{session_id}/state session_id=abc -> 401",
    ]
    assert all(r.levelno == logging.INFO for r in refused)
    assert not any("not-a-token" in r.getMessage() for r in caplog_server.records)


def test_the_request_context_never_holds_a_token():
    class Route:
        path = "/s/{token}"

    scope = {"type": "http", "method": "GET", "route": Route(), "path_params": {"token": "participant-secret"}}
    assert request_context(scope) == "GET /s/{token}"


def test_an_unhandled_error_is_logged_with_its_request(caplog_server):
    app = FastAPI()
    app.add_middleware(RequestLog)

    @app.get("/api/studies/{study_id}/broken")
    def broken(study_id: str):
        raise RuntimeError("disk on fire")

    with TestClient(app, raise_server_exceptions=False) as client:
        assert client.get("/api/studies/s1/broken").status_code == 500
    errors = [r for r in caplog_server.records if r.levelno == logging.ERROR and r.name == "trustseek.server.middleware"]
    assert [r.getMessage() for r in errors] == [
        "GET /api/studies/{study_id}/broken study_id=s1 failed: RuntimeError: disk on fire"
    ]
