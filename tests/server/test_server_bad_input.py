"""Bad input is refused with a 4xx and a JSON ``detail``, never a 5xx, and the connection is
kept (over real HTTP: uvicorn closes the connection after a 500).  Also: strict types,
conflicting replays, formula escaping in the events CSV, documented error responses."""

from __future__ import annotations

import io
import json

import httpx
import pandas as pd
import pytest

from trustseek.testing.servers import ThreadServer

TOKEN = "bad-input-token"
H = {"Authorization": f"Bearer {TOKEN}"}
JSON = {"content-type": "application/json"}


@pytest.fixture(scope="module")
def http(tmp_path_factory):
    db = f"sqlite:///{tmp_path_factory.mktemp('bad') / 'bad.sqlite'}"
    with ThreadServer(db, TOKEN) as url, httpx.Client(base_url=url, timeout=30) as c:
        yield c


def _study(http, **over):
    body = {"name": "bad", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 4}}}], **over}
    r = http.post("/api/studies", json=body, headers=H)
    assert r.status_code == 201, r.text
    return r.json()


def _participant(http, **over):
    st = _study(http, **over)
    s = http.post(f"/api/studies/{st['id']}/sessions", json={"count": 1}, headers=H).json()[0]
    ph = {"Authorization": f"Bearer {s['token']}"}
    base = f"/api/sessions/{s['session_id']}"
    assert http.post(f"{base}/consent", json={"agree": True}, headers=ph).status_code == 200
    return st, base, ph


def _deploy(http, **body):
    r = http.post("/api/deploy/sessions", json={"policy": {"kind": "never-ask"}, **body}, headers=H)
    assert r.status_code == 201, r.text
    d = r.json()
    return d, {"Authorization": f"Bearer {d['token']}"}


def refused(http, path, body, headers, status, words=()):
    """POST ``body`` (a dict, or raw JSON text with NaN/Infinity literals): a 4xx with a JSON
    detail naming ``words``, on a connection that stays open and answers the next request."""
    raw = body.encode() if isinstance(body, str) else json.dumps(body).encode()
    r = http.post(path, content=raw, headers={**headers, **JSON})
    assert r.status_code == status, r.text
    assert r.headers.get("connection", "").lower() != "close"
    detail = json.dumps(r.json()["detail"])
    for w in words:
        assert w in detail, detail
    assert http.get("/api/health").status_code == 200
    return r.json()["detail"]


# --------------------------------------------------------------------------- 500s on bad input


@pytest.mark.parametrize("field", ["model", "task"])
def test_unknown_deploy_preset_is_refused(http, field):
    refused(http, "/api/deploy/sessions", {field: "no-such-preset"}, H, 422, [f"unknown {field} preset", "no-such-preset"])


def test_huge_event_trial_number_is_refused(http):
    _, base, ph = _participant(http)
    refused(http, f"{base}/events", {"events": [{"type": "x", "trial": 10**20}]}, ph, 422, ["trial", "less than or equal"])
    refused(http, f"{base}/events", '{"events": [{"type": "x", "trial": 1e20}]}', ph, 422, ["trial"])


def test_nan_effort_is_refused(http):
    _, base, ph = _participant(http)
    body = '{"trial": 1, "submission_id": "n1", "human_action": "rely", "effort_ms": NaN}'
    detail = refused(http, f"{base}/trials", body, ph, 422, ["effort_ms", "finite"])
    assert detail[0]["input"] is None  # echoed as the project's JSON writes a non-finite number (json_safe)
    assert http.get(f"{base}/state", headers=ph).json()["trials_done"] == 0


def test_nan_self_report_is_refused(http):
    _, base, ph = _participant(http, self_report="trial")
    r = http.post(f"{base}/trials", json={"trial": 1, "submission_id": "r1", "human_action": "rely"}, headers=ph)
    assert r.status_code == 200, r.text
    refused(http, f"{base}/reports", '{"after_trial": 1, "value": NaN}', ph, 422, ["value", "finite"])
    refused(http, f"{base}/reports", '{"after_trial": 1, "value": -Infinity}', ph, 422, ["value"])


def test_deploy_token_posting_participant_trials_is_refused(http):
    d, dh = _deploy(http)
    sid = d["session_id"]
    r = http.post(f"/api/deploy/sessions/{sid}/decide", json={"trial": 1, "complexity": "high"}, headers=dh)
    assert r.status_code == 200, r.text
    for human in ("rely", "intervene"):
        for n in (1, 2):
            body = {"trial": n, "submission_id": f"d{n}", "human_action": human}
            refused(http, f"/api/sessions/{sid}/trials", body, dh, 409, ["deploy session"])
    refused(http, f"/api/sessions/{sid}/reports", {"after_trial": 1, "value": 50}, dh, 409, ["deploy session"])
    # the decision is untouched
    r = http.post(
        f"/api/deploy/sessions/{sid}/observe", json={"trial": 1, "human_action": "rely", "outcome": "success"}, headers=dh
    )
    assert r.status_code == 200, r.text


# --------------------------------------------------------------------------- strict types


def test_non_finite_numbers_and_wrong_types_are_refused(http):
    _, base, ph = _participant(http, self_report="trial")
    refused(http, f"{base}/events", '{"events": [{"type": "x", "t": Infinity}]}', ph, 422, ['"t"', "finite"])
    refused(http, f"{base}/events", '{"events": [{"type": "x", "data": {"v": [1, NaN]}}]}', ph, 422, ["data.v[1]"])
    refused(http, f"{base}/events", {"events": [{"type": "x", "trial": True}]}, ph, 422, ["trial"])
    refused(http, f"{base}/consent", {"agree": 1}, ph, 422, ["agree"])
    r = http.post(f"{base}/trials", json={"trial": 1, "submission_id": "s1", "human_action": "rely"}, headers=ph)
    assert r.status_code == 200, r.text
    refused(http, f"{base}/reports", {"after_trial": True, "value": 50}, ph, 422, ["after_trial"])
    refused(http, f"{base}/reports", {"after_trial": 1, "value": "50"}, ph, 422, ["value"])
    refused(http, f"{base}/trials", {"trial": "2", "submission_id": "s2", "human_action": "rely"}, ph, 422, ["trial"])
    refused(http, "/api/deploy/sessions", {"seed": False}, H, 422, ["seed"])
    refused(http, "/api/studies", {"name": "x", "seed": True, "blocks": []}, H, 422, ["seed"])
    d, dh = _deploy(http)
    refused(http, f"/api/deploy/sessions/{d['session_id']}/decide", {"trial": True, "complexity": "low"}, dh, 422, ["trial"])
    # integers are still numbers: a report of 50 (not 50.0) is taken
    r = http.post(f"{base}/reports", json={"after_trial": 1, "value": 50}, headers=ph)
    assert r.status_code == 200 and r.json()["report"]["value"] == 50.0


# --------------------------------------------------------------------------- replays


def test_replay_with_another_human_action_is_refused(http):
    st, base, ph = _participant(http)
    first = {"trial": 1, "submission_id": "sub-1", "human_action": "rely"}
    r = http.post(f"{base}/trials", json=first, headers=ph)
    assert r.status_code == 200 and r.json()["duplicate"] is False
    refused(http, f"{base}/trials", {**first, "human_action": "intervene"}, ph, 409, ["sub-1", "human_action"])
    again = http.post(f"{base}/trials", json=first, headers=ph)  # a true retry is still a duplicate
    assert again.status_code == 200 and again.json()["duplicate"] is True
    assert again.json()["trial"]["human_action"] == "rely"
    frame = pd.read_csv(io.BytesIO(http.get(f"/api/studies/{st['id']}/export", headers=H).content))
    assert frame["human_action"].tolist() == ["rely"]


# --------------------------------------------------------------------------- export


def test_events_csv_escapes_spreadsheet_formulas(http):
    st, base, ph = _participant(http)
    texts = ['=HYPERLINK("http://x.example","click")', "+1", "-2", "@SUM(A1)", "\tx", "\rx", "plain", "a=b"]
    r = http.post(f"{base}/events", json={"events": [{"type": t, "data": {"note": t}} for t in texts]}, headers=ph)
    assert r.status_code == 200, r.text
    csv = http.get(f"/api/studies/{st['id']}/export", params={"table": "events"}, headers=H)
    events = pd.read_csv(io.BytesIO(csv.content), keep_default_na=False)
    got = events["type"].tolist()[-len(texts) :]
    assert got == ["'" + t for t in texts[:6]] + ["plain", "a=b"]
    assert all(
        not str(v).startswith(("=", "+", "-", "@", "\t", "\r")) for col in events for v in events[col] if isinstance(v, str)
    )
    # Parquet keeps the text as it was posted (it is not opened by spreadsheets as formulas)
    pq = http.get(f"/api/studies/{st['id']}/export", params={"table": "events", "format": "parquet"}, headers=H)
    assert pd.read_parquet(io.BytesIO(pq.content))["type"].tolist()[-len(texts) :] == texts


# --------------------------------------------------------------------------- OpenAPI


@pytest.mark.parametrize(
    ("method", "path", "codes"),
    [
        ("post", "/api/studies", {"400", "401", "403"}),
        ("get", "/api/studies/{study_id}", {"401", "403", "404"}),
        ("post", "/api/studies/{study_id}/sessions", {"400", "401", "403", "404", "409"}),
        ("get", "/api/studies/{study_id}/export", {"401", "403", "404"}),
        ("post", "/api/sessions/{session_id}/trials", {"400", "401", "403", "409"}),
        ("post", "/api/sessions/{session_id}/reports", {"401", "403", "409"}),
        ("get", "/api/session", {"401", "409"}),
        ("post", "/api/deploy/sessions", {"400", "401", "403"}),
        ("post", "/api/deploy/sessions/{session_id}/decide", {"400", "401", "403", "404", "409"}),
        ("post", "/api/deploy/sessions/{session_id}/observe", {"400", "401", "403", "404", "409"}),
    ],
)
def test_openapi_declares_the_error_responses(http, method, path, codes):
    spec = http.get("/openapi.json").json()
    responses = spec["paths"][path][method]["responses"]
    assert codes <= set(responses), sorted(responses)
    for code in codes:
        schema = responses[code]["content"]["application/json"]["schema"]
        assert schema == {"$ref": "#/components/schemas/ErrorOut"}
    assert "detail" in spec["components"]["schemas"]["ErrorOut"]["properties"]
