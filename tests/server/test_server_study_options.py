"""Study options and the bounds on participants' writes: practice trials, questionnaires,
online panels; writes refused after a session ends; body sizes capped and authenticated before
they are read; event counts and sizes bounded."""

from __future__ import annotations

import asyncio
import io
import json

import pandas as pd
import pytest
from fastapi.testclient import TestClient
from hypothesis import given, settings
from hypothesis import strategies as st_

from trustseek.data.trials import read_trials
from trustseek.server import create_app
from trustseek.server.middleware import SESSION_BODY_LIMIT
from trustseek.server.sessions import MAX_EVENTS_PER_TRIAL

TOKEN = "experimenter-secret"
H = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture
def client(tmp_path):
    with TestClient(create_app(f"sqlite:///{tmp_path / 'opts.sqlite'}", token=TOKEN)) as c:
        yield c


def make_study(client, **over) -> dict:
    body = {"name": "opts", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "high"]}}]}
    body.update(over)
    r = client.post("/api/studies", json=body, headers=H)
    assert r.status_code == 201, r.text
    return r.json()


def join(client, study_id) -> tuple[str, dict]:
    (info,) = client.post(f"/api/studies/{study_id}/sessions", json={"count": 1}, headers=H).json()
    return info["session_id"], {"Authorization": f"Bearer {info['token']}"}


def do_trial(client, sid, ph, state, human="rely") -> dict:
    cur = state["current"]
    human = "intervene" if cur["robot_action"] == "ask" else human
    body = {"trial": cur["trial"], "submission_id": f"s{cur['trial']}", "human_action": human}
    r = client.post(f"/api/sessions/{sid}/trials", json=body, headers=ph)
    assert r.status_code == 200, r.text
    return r.json()


def export(client, study_id, **params) -> pd.DataFrame:
    r = client.get(f"/api/studies/{study_id}/export", params=params, headers=H)
    assert r.status_code == 200, r.text
    return pd.read_csv(io.BytesIO(r.content))


# --------------------------------------------------------------------------- practice


def test_practice_trials_come_first_are_logged_and_left_out_of_the_analysis(client):
    st = make_study(
        client,
        practice={"trials": ["low", "high"], "policy": {"kind": "always-ask"}},
        blocks=[
            {"name": "a", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["high", "low"]}},
            {"name": "b", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}},
        ],
        self_report="block",
    )
    sid, ph = join(client, st["id"])
    state = client.post(f"/api/sessions/{sid}/consent", json={"agree": True}, headers=ph).json()
    assert state["practice_trials"] == 2 and state["trials_total"] == 5
    seen = []
    while state["current"] is not None or state["report_due"] is not None:
        if state["report_due"] is not None:
            r = client.post(f"/api/sessions/{sid}/reports", json={"after_trial": state["report_due"], "value": 60}, headers=ph)
            assert r.status_code == 200, r.text
            state = r.json()["state"]
            continue
        cur = state["current"]
        seen.append((cur["trial"], cur["practice"], cur["robot_action"], cur["block_position"]))
        res = do_trial(client, sid, ph, state)
        if cur["practice"]:  # practice scores nothing
            assert res["state"]["score"] == 0.0 and res["trial"]["practice"] is True
        state = res["state"]
    assert seen[:2] == [(1, True, "ask", 0), (2, True, "ask", 0)]
    assert [s[1] for s in seen[2:]] == [False, False, False]
    analysis = export(client, st["id"])
    assert analysis["trial"].tolist() == [1, 2, 3] and analysis["session_trial"].tolist() == [3, 4, 5]
    assert not analysis["practice"].any()
    assert analysis["robot_action"].tolist() == ["autonomous"] * 3
    first = analysis.iloc[0]
    assert first["belief"] == pytest.approx(0.5, abs=0.5)  # the model's initial belief, practice left it alone
    full = export(client, st["id"], practice="true")
    assert full["practice"].tolist() == [True, True, False, False, False]
    assert full["block_name"].tolist()[:2] == ["practice", "practice"]
    assert len(read_trials(analysis)) == 3
    # self-reports follow blocks, never practice; they join the analysis log by trial
    reports = export(client, st["id"], table="reports")
    assert reports["trial"].tolist() == [2, 3] and reports["session_trial"].tolist() == [4, 5]
    # the initial belief of the first analysed trial equals the model's, as without practice
    st2 = make_study(client, blocks=[{"name": "a", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["high"]}}])
    sid2, ph2 = join(client, st2["id"])
    do_trial(client, sid2, ph2, client.post(f"/api/sessions/{sid2}/consent", json={"agree": True}, headers=ph2).json())
    assert export(client, st2["id"])["belief"].iloc[0] == pytest.approx(first["belief"], abs=1e-12)


def test_practice_names_known_complexities(client):
    r = client.post(
        "/api/studies",
        json={
            "name": "x",
            "practice": {"trials": ["medium"]},
            "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}}],
        },
        headers=H,
    )
    assert r.status_code == 400 and "practice.trials" in r.text


# --------------------------------------------------------------------------- questionnaires


def test_questionnaires_are_required_item_by_item_and_export_long(client):
    st = make_study(
        client,
        blocks=[
            {"name": "a", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "high"]}},
            {"name": "b", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}},
        ],
        questionnaires=[
            {
                "name": "quick",
                "when": "block",
                "items": [{"id": "trust", "text": "I trust the robot."}, {"id": "predict", "text": "I can predict it."}],
                "scale": {"min": 1, "max": 5, "anchors": ["disagree", "agree"]},
            },
            {"template": "jian2000", "when": "end"},
        ],
    )
    config = client.get(f"/api/studies/{st['id']}", headers=H).json()["config"]
    jian = config["questionnaires"][1]
    assert len(jian["items"]) == 12 and jian["scale"]["min"] == 1 and jian["scale"]["max"] == 7 and "Jian" in jian["source"]
    sid, ph = join(client, st["id"])
    state = client.post(f"/api/sessions/{sid}/consent", json={"agree": True}, headers=ph).json()
    state = do_trial(client, sid, ph, state)["state"]
    assert state["questionnaire"] is None
    state = do_trial(client, sid, ph, state)["state"]
    q = state["questionnaire"]
    assert q["name"] == "quick" and q["after_trial"] == 2 and state["current"] is None  # asked before trial 3
    url = f"/api/sessions/{sid}/questionnaires"
    skip = client.post(
        f"/api/sessions/{sid}/trials", json={"trial": 3, "submission_id": "s3", "human_action": "rely"}, headers=ph
    )
    assert skip.status_code == 409 and "answer" in skip.text  # no trial before the questions are answered
    # every item, each a whole point of the scale
    partial = client.post(url, json={"questionnaire": "quick", "after_trial": 2, "answers": {"trust": 4}}, headers=ph)
    assert partial.status_code == 400 and "predict" in partial.text
    off = client.post(url, json={"questionnaire": "quick", "after_trial": 2, "answers": {"trust": 6, "predict": 2}}, headers=ph)
    assert off.status_code == 400
    early = client.post(url, json={"questionnaire": "quick", "after_trial": 1, "answers": {"trust": 4, "predict": 2}}, headers=ph)
    assert early.status_code == 409
    ok = client.post(url, json={"questionnaire": "quick", "after_trial": 2, "answers": {"trust": 4, "predict": 2}}, headers=ph)
    assert ok.status_code == 200, ok.text
    state = ok.json()["state"]
    assert state["questionnaire"] is None and state["current"]["trial"] == 3
    again = client.post(url, json={"questionnaire": "quick", "after_trial": 2, "answers": {"trust": 4, "predict": 2}}, headers=ph)
    assert again.status_code == 200 and again.json()["answers"]["duplicate"] is True
    changed = client.post(
        url, json={"questionnaire": "quick", "after_trial": 2, "answers": {"trust": 5, "predict": 2}}, headers=ph
    )
    assert changed.status_code == 409
    state = do_trial(client, sid, ph, state)["state"]
    assert state["status"] == "done" and not state["ended"]
    assert [x["name"] for x in (state["questionnaire"],)] == ["quick"]
    state = client.post(
        url, json={"questionnaire": "quick", "after_trial": 3, "answers": {"trust": 3, "predict": 3}}, headers=ph
    ).json()["state"]
    assert state["questionnaire"]["name"] == "trust-in-automation"
    answers = {i["id"]: 1 + k % 7 for k, i in enumerate(jian["items"])}
    r = client.post(url, json={"questionnaire": "trust-in-automation", "after_trial": 3, "answers": answers}, headers=ph)
    assert r.status_code == 200, r.text
    assert r.json()["state"]["ended"] is True
    reports = export(client, st["id"], table="reports")
    assert len(reports) == 2 + 2 + 12
    assert reports.columns[:4].tolist() == ["participant", "trial", "session_trial", "block"]
    quick = reports[reports.questionnaire == "quick"]
    assert sorted(zip(quick["trial"], quick["item"], quick["value"], strict=True)) == [
        (2, "predict", 2.0),
        (2, "trust", 4.0),
        (3, "predict", 3.0),
        (3, "trust", 3.0),
    ]
    j = reports[reports.questionnaire == "trust-in-automation"]
    assert j["reverse"].sum() == 5 and (j["trial"] == 3).all()
    # reports join the trial log by participant and trial
    merged = export(client, st["id"]).merge(reports, on=["participant", "trial"])
    assert len(merged) == len(reports)


def test_unknown_template_is_refused(client):
    r = client.post(
        "/api/studies",
        json={
            "name": "x",
            "questionnaires": [{"template": "nope"}],
            "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}}],
        },
        headers=H,
    )
    assert r.status_code == 400 and "jian2000" in r.text


# --------------------------------------------------------------------------- panels


def test_panel_ids_are_stored_and_the_code_is_given_only_at_the_end(client):
    st = make_study(
        client,
        panel={"completion_code": "C0DE42", "redirect_url": "https://panel.example/done?cc={completion_code}"},
    )
    sid, ph = join(client, st["id"])
    before = client.get("/api/session", headers=ph).json()
    assert before["panel_params"] == ["PROLIFIC_PID", "STUDY_ID", "SESSION_ID"] and before["completion"] is None
    ids = {"PROLIFIC_PID": "abc123", "STUDY_ID": "st9", "SESSION_ID": "se7", "OTHER": "dropped"}
    state = client.post(f"/api/sessions/{sid}/consent", json={"agree": True, "panel": ids}, headers=ph).json()
    assert "C0DE42" not in json.dumps(state)
    state = do_trial(client, sid, ph, state)["state"]
    assert state["completion"] is None
    state = do_trial(client, sid, ph, state)["state"]
    assert state["ended"] and state["completion"] == {"code": "C0DE42", "redirect_url": "https://panel.example/done?cc=C0DE42"}
    rec = export(client, st["id"], table="sessions")
    assert json.loads(rec["panel"].iloc[0]) == {"PROLIFIC_PID": "abc123", "STUDY_ID": "st9", "SESSION_ID": "se7"}


# --------------------------------------------------------------------------- writes after the end, sizes


def test_a_finished_session_takes_no_more_writes(client):
    st = make_study(client, self_report="block")
    sid, ph = join(client, st["id"])
    state = client.post(f"/api/sessions/{sid}/consent", json={"agree": True}, headers=ph).json()
    state = do_trial(client, sid, ph, do_trial(client, sid, ph, state)["state"])["state"]
    assert state["report_due"] == 2 and not state["ended"]
    events = {"events": [{"type": "note", "trial": 2}]}
    assert client.post(f"/api/sessions/{sid}/events", json=events, headers=ph).status_code == 200  # still answering
    assert client.post(f"/api/sessions/{sid}/reports", json={"after_trial": 2, "value": 40}, headers=ph).status_code == 200
    assert client.get("/api/session", headers=ph).json()["ended"] is True
    assert client.post(f"/api/sessions/{sid}/events", json=events, headers=ph).status_code == 409
    assert client.post(f"/api/sessions/{sid}/reports", json={"after_trial": 1, "value": 40}, headers=ph).status_code == 409
    late = client.post(f"/api/sessions/{sid}/consent", json={"agree": True, "events": events["events"]}, headers=ph)
    assert late.status_code == 409
    assert export(client, st["id"], table="reports")["value"].tolist() == [40.0]
    assert len(export(client, st["id"], table="events")) == 1


def test_event_bounds_per_trial_and_per_event(client):
    st = make_study(client)
    sid, ph = join(client, st["id"])
    client.post(f"/api/sessions/{sid}/consent", json={"agree": True}, headers=ph)
    big = {"events": [{"type": "x", "data": {"blob": "a" * 5000}}]}
    assert client.post(f"/api/sessions/{sid}/events", json=big, headers=ph).status_code == 422
    batch = {"events": [{"type": "x", "trial": 1}] * 1000}
    codes = [client.post(f"/api/sessions/{sid}/events", json=batch, headers=ph).status_code for _ in range(3)]
    assert codes == [200, 200, 413] and MAX_EVENTS_PER_TRIAL == 2000
    assert client.post(f"/api/sessions/{sid}/events", json={"events": [{"type": "x", "trial": 2}]}, headers=ph).status_code == 200


def test_a_retried_event_batch_is_stored_once(client):
    """The page retries a batch whose answer was lost with the same batch id: stored once.
    Without an id every post is stored (older pages)."""
    st = make_study(client)
    sid, ph = join(client, st["id"])
    client.post(f"/api/sessions/{sid}/consent", json={"agree": True}, headers=ph)
    body = {"events": [{"type": "outcome_shown", "trial": 1}, {"type": "note", "trial": 1}], "batch": "b-0123abcd"}
    first = client.post(f"/api/sessions/{sid}/events", json=body, headers=ph).json()
    again = client.post(f"/api/sessions/{sid}/events", json=body, headers=ph).json()
    assert first == {"stored": 2, "duplicate": False} and again == {"stored": 0, "duplicate": True}
    other = client.post(f"/api/sessions/{sid}/events", json={**body, "batch": "b-other"}, headers=ph).json()
    assert other == {"stored": 2, "duplicate": False}
    plain = {"events": [{"type": "note", "trial": 1}]}
    assert [client.post(f"/api/sessions/{sid}/events", json=plain, headers=ph).json()["stored"] for _ in range(2)] == [1, 1]
    ev = client.get(f"/api/studies/{st['id']}/export", params={"table": "events"}, headers=H)
    assert ev.status_code == 200, ev.text
    types = pd.read_csv(io.BytesIO(ev.content))["type"].tolist()
    assert len(types) == 6 and types.count("outcome_shown") == 2  # first batch, the other batch; not the repeat
    bad = client.post(f"/api/sessions/{sid}/events", json={**body, "batch": "no spaces allowed"}, headers=ph)
    assert bad.status_code == 422


def test_large_bodies_are_refused_with_413(client):
    st = make_study(client)
    sid, ph = join(client, st["id"])
    body = json.dumps({"events": [{"type": "x", "data": {"k": "v" * 3000}}] * 100}).encode()
    assert len(body) > SESSION_BODY_LIMIT
    r = client.post(f"/api/sessions/{sid}/events", content=body, headers={**ph, "Content-Type": "application/json"})
    assert r.status_code == 413
    assert len(export(client, st["id"], table="events")) == 0


def test_unauthenticated_writes_are_refused_before_the_body_is_read(client):
    st = make_study(client)
    sid, _ = join(client, st["id"])
    junk = b"not json at all " * 1000
    for headers, status in (({}, 401), ({"Authorization": "Bearer nope"}, 401)):
        r = client.post(f"/api/sessions/{sid}/events", content=junk, headers=headers)
        assert r.status_code == status, r.text
    assert client.post("/api/studies", content=junk, headers={"Authorization": "Bearer nope"}).status_code == 403
    # at the ASGI level: the body is never received
    app = client.app
    sent: list[dict] = []

    async def receive():
        raise AssertionError("the body was read")

    async def send(message):
        sent.append(message)

    for headers in ([], [(b"authorization", b"Bearer unknown")]):
        sent.clear()
        scope = {
            "type": "http",
            "method": "POST",
            "path": f"/api/sessions/{sid}/events",
            "raw_path": f"/api/sessions/{sid}/events".encode(),
            "query_string": b"",
            "headers": [(b"content-length", b"52000000"), *headers],
            "http_version": "1.1",
            "scheme": "http",
            "server": ("test", 80),
            "client": ("test", 1),
            "root_path": "",
        }
        asyncio.run(app(scope, receive, send))
        assert sent[0]["status"] == 401


def test_migration_0002_gives_sessions_made_before_it_a_secret(tmp_path):
    """A database at revision 0001 (no secrets) upgraded by the server: every study session gets
    a secret of its own and goes on; the downgrade removes the new columns and table."""
    from alembic import command
    from alembic.config import Config
    from sqlalchemy import create_engine, inspect, text

    from trustseek.server.db import MIGRATIONS

    url = f"sqlite:///{tmp_path / 'old.sqlite'}"
    with TestClient(create_app(url, token=TOKEN)) as c:
        st = make_study(c)
        sids = [join(c, st["id"]) for _ in range(2)]
    eng = create_engine(url)
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    with eng.begin() as conn:
        cfg.attributes["connection"] = conn
        command.downgrade(cfg, "0001")
    assert "secret" not in {col["name"] for col in inspect(eng).get_columns("sessions")}
    assert "answers" not in inspect(eng).get_table_names()
    eng.dispose()
    with TestClient(create_app(url, token=TOKEN)) as c:
        with create_engine(url).connect() as conn:
            secrets_ = conn.execute(text("select secret from sessions order by id")).scalars().all()
        assert len(secrets_) == 2 and all(s and len(s) == 32 for s in secrets_) and len(set(secrets_)) == 2
        sid, ph = sids[0]
        state = c.post(f"/api/sessions/{sid}/consent", json={"agree": True}, headers=ph).json()
        assert do_trial(c, sid, ph, state)["trial"]["trial"] == 1


@settings(max_examples=300, deadline=None)
@given(
    lo=st_.integers(-5, 5),
    width=st_.integers(1, 10),
    n_items=st_.integers(1, 6),
    answers=st_.dictionaries(
        st_.sampled_from([f"i{k}" for k in range(8)]),
        st_.one_of(st_.integers(-20, 20), st_.floats(-20, 20, allow_nan=False)),
        max_size=8,
    ),
)
def test_an_answer_is_accepted_iff_it_gives_every_item_a_point_of_the_scale(lo, width, n_items, answers):
    from trustseek.server.answers import answer_problems

    q = {"name": "q", "items": [{"id": f"i{k}", "text": "t"} for k in range(n_items)], "scale": {"min": lo, "max": lo + width}}
    complete = set(answers) == {f"i{k}" for k in range(n_items)}
    on_scale = all(v in range(lo, lo + width + 1) for v in answers.values())
    assert (answer_problems(q, answers) == []) == (complete and on_scale)
