"""The comprehension quiz after the instructions (retries, then the configured outcome) and
attention-check items in questionnaires, recorded with their answers."""

from __future__ import annotations

import io

import pandas as pd
import pytest
from fastapi.testclient import TestClient

from trustseek.server import create_app

TOKEN = "experimenter-secret"
H = {"Authorization": f"Bearer {TOKEN}"}
QUIZ = {
    "questions": [
        {"id": "ask", "text": "When the robot asks for help, you...", "options": ["watch", "drive it"], "answer": 1},
        {"id": "space", "text": "Space...", "options": ["intervenes", "pauses"], "answer": 0},
    ],
    "attempts": 2,
}


@pytest.fixture
def client(tmp_path):
    with TestClient(create_app(f"sqlite:///{tmp_path / 'checks.sqlite'}", token=TOKEN)) as c:
        yield c


def start(client, **over) -> tuple[str, dict, dict, str]:
    body = {
        "name": "checks",
        "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}}],
        "panel": {"completion_code": "DONE"},
        **over,
    }
    r = client.post("/api/studies", json=body, headers=H)
    assert r.status_code == 201, r.text
    (info,) = client.post(f"/api/studies/{r.json()['id']}/sessions", json={"count": 1}, headers=H).json()
    h = {"Authorization": f"Bearer {info['token']}"}
    st = client.post(f"/api/sessions/{info['session_id']}/consent", json={"agree": True}, headers=h).json()
    return info["session_id"], h, st, r.json()["id"]


def quiz(client, sid, h, attempt, **answers):
    return client.post(f"/api/sessions/{sid}/quiz", json={"attempt": attempt, "answers": answers}, headers=h)


def test_the_quiz_comes_before_the_first_trial_and_a_retry_passes(client):
    sid, h, st, study = start(client, quiz=QUIZ)
    assert st["current"] is None and st["quiz"]["attempt"] == 1
    assert "answer" not in st["quiz"]["questions"][0]  # the page never gets the right answers
    refused = client.post(
        f"/api/sessions/{sid}/trials", json={"trial": 1, "submission_id": "a", "human_action": "rely"}, headers=h
    )
    assert refused.status_code == 409
    assert quiz(client, sid, h, 1, ask=0).status_code == 400  # every question
    r = quiz(client, sid, h, 1, ask=0, space=0)
    assert r.json()["wrong"] == ["ask"] and r.json()["state"]["quiz"]["attempt"] == 2
    assert r.json()["state"]["quiz"]["wrong"] == ["ask"]
    assert quiz(client, sid, h, 1, ask=0, space=0).json()["duplicate"] is True  # a retry of a stored attempt
    assert quiz(client, sid, h, 1, ask=1, space=0).status_code == 409  # the same attempt, other answers
    r = quiz(client, sid, h, 2, ask=1, space=0)
    assert r.json()["wrong"] == [] and r.json()["state"]["quiz"] is None and r.json()["state"]["current"]["trial"] == 1
    sessions = pd.read_csv(io.BytesIO(client.get(f"/api/studies/{study}/export?table=sessions", headers=H).content))
    assert sessions[["quiz_attempts", "quiz_outcome"]].values.tolist() == [[2, "passed"]]


@pytest.mark.parametrize("on_fail", ["end", "continue"])
def test_failing_every_attempt_has_the_configured_outcome(client, on_fail):
    sid, h, _, study = start(client, quiz={**QUIZ, "on_fail": on_fail, "fail_code": "SCREENED-OUT"})
    quiz(client, sid, h, 1, ask=0, space=1)
    r = quiz(client, sid, h, 2, ask=0, space=1).json()["state"]
    if on_fail == "end":
        assert r["ended"] and r["screened"] and r["current"] is None
        assert r["completion"]["code"] == "SCREENED-OUT"  # the panel's screen-out code, never the completion code
    else:
        assert not r["ended"] and r["current"]["trial"] == 1
    sessions = pd.read_csv(io.BytesIO(client.get(f"/api/studies/{study}/export?table=sessions", headers=H).content))
    assert sessions["quiz_outcome"].tolist() == ["failed"]


def test_attention_checks_are_recorded_with_their_answers(client):
    q = {
        "name": "end",
        "items": [{"id": "trust", "text": "I trust the robot."}, {"id": "attn", "text": "Please select 2.", "check": 2}],
        "scale": {"min": 1, "max": 5},
    }
    sid, h, st, study = start(client, questionnaires=[q])
    cur = st["current"]
    st = client.post(f"/api/sessions/{sid}/trials", json={"trial": 1, "submission_id": "a", "human_action": "rely"}, headers=h)
    body = {"questionnaire": "end", "after_trial": 1, "answers": {"trust": 4, "attn": 3}}
    assert cur and client.post(f"/api/sessions/{sid}/questionnaires", json=body, headers=h).status_code == 200
    reports = pd.read_csv(io.BytesIO(client.get(f"/api/studies/{study}/export?table=reports", headers=H).content))
    row = reports.set_index("item").loc["attn"]
    assert row["check"] == 2 and row["value"] == 3 and not row["check_passed"]
    assert pd.isna(reports.set_index("item").loc["trust", "check_passed"])
    sessions = pd.read_csv(io.BytesIO(client.get(f"/api/studies/{study}/export?table=sessions", headers=H).content))
    assert sessions["checks_failed"].tolist() == [1]
    bad = {**q, "items": [{"id": "attn", "text": "Select 9.", "check": 9}]}
    r = client.post(
        "/api/studies",
        json={
            "name": "x",
            "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}}],
            "questionnaires": [bad],
        },
        headers=H,
    )
    assert r.status_code == 400 and "attention check" in r.text


def test_a_repeat_of_the_last_answers_after_the_end_is_a_duplicate_not_a_refusal(client):
    """The answers that end a session, posted again (a retry whose answer was lost, or a second
    tab), get the stored answers back; before, the repeat was refused (409) and the page stuck."""
    q = {"name": "end", "items": [{"id": "a", "text": "A."}], "scale": {"min": 1, "max": 5}}
    sid, h, _, _ = start(client, questionnaires=[q])
    client.post(f"/api/sessions/{sid}/trials", json={"trial": 1, "submission_id": "a", "human_action": "rely"}, headers=h)
    body = {"questionnaire": "end", "after_trial": 1, "answers": {"a": 4}}
    first = client.post(f"/api/sessions/{sid}/questionnaires", json=body, headers=h)
    assert first.status_code == 200 and first.json()["state"]["ended"]
    again = client.post(f"/api/sessions/{sid}/questionnaires", json=body, headers=h)
    assert again.status_code == 200 and again.json()["answers"]["duplicate"] is True
    other = client.post(f"/api/sessions/{sid}/questionnaires", json={**body, "answers": {"a": 2}}, headers=h)
    assert other.status_code == 409


@pytest.mark.parametrize(
    ("body", "status", "wanted"),
    [
        # a field's problem and a block's: both named (before: only the field's)
        (
            {"task": "nope", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["medium"]}}]},
            422,
            ["unknown task preset", "blocks[0].schedule names unknown complexities ['medium']"],
        ),
        (
            {"animation_speed": 0, "blocks": [{"policy": {"kind": "bogus"}, "schedule": {"trials": ["low"]}}]},
            422,
            ["greater than 0.05", "blocks[0].policy.kind is 'bogus'"],
        ),
        # an invalid model and a block: both (before: the model's only)
        (
            {"model": {"format": "x"}, "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["medium"]}}]},
            400,
            ["model: format is 'x'", "blocks[0].schedule names unknown complexities"],
        ),
        # a schedule with two problems: both
        (
            {"blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": -1}, "trials": ["low"]}}]},
            422,
            ["exactly one of 'counts' or 'trials'", "counts must be non-negative"],
        ),
    ],
)
def test_a_study_with_several_problems_is_refused_naming_them_all(client, body, status, wanted):
    r = client.post("/api/studies", json={"name": "several", **body}, headers=H)
    assert r.status_code == status, r.text
    for w in wanted:
        assert w in r.text, (w, r.text)
