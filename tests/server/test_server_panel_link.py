"""The study link of an online panel (``/join/<token>``) and the study's lifecycle: one session
per panel id (also under concurrent arrivals), balanced block orders, the quota, draft / open /
paused / closed, pilot and preview sessions left out of the analysis export, revoked links."""

from __future__ import annotations

import io
import threading
from urllib.parse import parse_qs, urlsplit

import pandas as pd
import pytest
from fastapi.testclient import TestClient

from server_checks import database_rows
from trustseek.server import create_app
from trustseek.testing.servers import TemporaryPostgres, postgres_binaries

TOKEN = "experimenter-secret"
H = {"Authorization": f"Bearer {TOKEN}"}
BLOCKS = [
    {"name": "a", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}},
    {"name": "b", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["high"]}},
]


@pytest.fixture
def client(tmp_path):
    with TestClient(create_app(f"sqlite:///{tmp_path / 'link.sqlite'}", token=TOKEN)) as c:
        yield c


@pytest.fixture(scope="module")
def pg_client():
    """The server on a throwaway PostgreSQL cluster (row locks and unique indexes of its own)."""
    if postgres_binaries() is None:
        pytest.skip("PostgreSQL server binaries not found; scripts/setup.sh installs Debian's postgresql package as root")
    cluster = TemporaryPostgres()
    try:
        with TestClient(create_app(cluster.start(), token=TOKEN)) as c:
            yield c
    finally:
        cluster.stop()


def make_study(client, status="open", **over) -> dict:
    body = {"name": "panel", "blocks": BLOCKS, "counterbalance": "rotate", "panel": {"completion_code": "C0DE"}, **over}
    r = client.post("/api/studies", json=body, headers=H, params={"status": status})
    assert r.status_code == 201, r.text
    return r.json()


def join(client, study, pid: str | None, **extra):
    q = {"PROLIFIC_PID": pid, "STUDY_ID": "s1", "SESSION_ID": f"x-{pid}", **extra} if pid else extra
    return client.get(urlsplit(study["link"]).path, params=q, follow_redirects=False)


def token_of(r) -> str:
    assert r.status_code == 303, r.text
    return urlsplit(r.headers["location"]).path.rsplit("/", 1)[-1]


def run_through(client, token: str, pid: str) -> dict:
    """Consent with the panel's ids and do every trial; returns the final state."""
    h = {"Authorization": f"Bearer {token}"}
    st = client.get("/api/session", headers=h).json()
    sid = st["session_id"]
    r = client.post(f"/api/sessions/{sid}/consent", json={"agree": True, "panel": {"PROLIFIC_PID": pid}}, headers=h)
    assert r.status_code == 200, r.text
    st = r.json()
    while st["current"]:
        cur = st["current"]
        human = "intervene" if cur["robot_action"] == "ask" else "rely"
        body = {"trial": cur["trial"], "submission_id": f"s{cur['trial']}", "human_action": human}
        r = client.post(f"/api/sessions/{sid}/trials", json=body, headers=h)
        assert r.status_code == 200, r.text
        st = r.json()["state"]
    return st


def export(client, study_id, table="trials", **params) -> pd.DataFrame:
    r = client.get(f"/api/studies/{study_id}/export", params={"table": table, **params}, headers=H)
    assert r.status_code == 200, r.text
    return pd.read_csv(io.BytesIO(r.content))


def test_a_panel_id_gets_one_session_resumed_and_a_page_once_completed(client):
    study = make_study(client)
    first = token_of(join(client, study, "pid-1"))
    assert token_of(join(client, study, "pid-1")) == first  # a reload or a second visit resumes it
    loc = join(client, study, "pid-1").headers["location"]
    assert parse_qs(urlsplit(loc).query)["PROLIFIC_PID"] == ["pid-1"]  # the page gets the ids for the consent
    st = run_through(client, first, "pid-1")
    assert st["ended"] and st["completion"]["code"] == "C0DE"
    again = join(client, study, "pid-1")
    assert again.status_code == 200 and "already completed" in again.text and "C0DE" not in again.text
    assert join(client, study, None).status_code == 400  # no panel id: a page asks for it
    assert client.get("/join/not-a-token").status_code == 404
    sessions = export(client, study["id"], "sessions")
    assert len(sessions) == 1 and sessions["panel_id"].tolist() == ["pid-1"]
    assert sessions["ended_at"].notna().all() and sessions["speed"].tolist() == [1.0]


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_concurrent_arrivals_of_one_panel_id_make_one_session_and_orders_stay_balanced(backend, request):
    client = request.getfixturevalue("client" if backend == "sqlite" else "pg_client")
    study = make_study(client, quota=7)
    tokens: list[str] = []
    lock = threading.Lock()

    def arrive(pid):
        t = token_of(join(client, study, pid))
        with lock:
            tokens.append((pid, t))

    threads = [threading.Thread(target=arrive, args=(f"pid-{i % 7}",)) for i in range(21)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    by_pid: dict[str, set[str]] = {}
    for pid, t in tokens:
        by_pid.setdefault(pid, set()).add(t)
    assert all(len(ts) == 1 for ts in by_pid.values()) and len(by_pid) == 7
    sessions = export(client, study["id"], "sessions")
    assert len(sessions) == 7 and client.get(f"/api/studies/{study['id']}", headers=H).json()["status"] == "closed"
    firsts = sessions["block_order"].str.slice(2, 3).value_counts()
    assert max(firsts) - min(firsts) <= 1, firsts


def test_the_same_panel_id_is_refused_in_a_second_session(client):
    study = make_study(client)
    links = client.post(f"/api/studies/{study['id']}/sessions", json={"count": 2}, headers=H).json()
    for i, link in enumerate(links):
        h = {"Authorization": f"Bearer {link['token']}"}
        r = client.post(
            f"/api/sessions/{link['session_id']}/consent", json={"agree": True, "panel": {"PROLIFIC_PID": "same"}}, headers=h
        )
        assert r.status_code == (200 if i == 0 else 409), r.text
    assert "already has a session" in r.json()["detail"]
    r = join(client, study, "same")  # the study link resumes that id's session
    assert token_of(r) == links[0]["token"]


def test_a_quota_closes_the_study(client):
    study = make_study(client, quota=2)
    token_of(join(client, study, "a"))
    token_of(join(client, study, "b"))
    r = join(client, study, "c")
    assert r.status_code == 409 and "The study is full" in r.text
    assert client.get(f"/api/studies/{study['id']}", headers=H).json()["status"] == "closed"
    assert token_of(join(client, study, "a"))  # an arrived participant may still finish


def test_lifecycle_draft_open_paused_closed(client):
    study = make_study(client, status="draft")
    sid = study["id"]
    assert join(client, study, "early").status_code == 409  # a draft takes no one through the link
    (pilot,) = client.post(f"/api/studies/{sid}/sessions", json={"count": 1}, headers=H).json()
    assert pilot["role"] == "pilot"  # links made in a draft are pilots
    run_through(client, pilot["token"], "pilot-1")
    status = lambda s: client.post(f"/api/studies/{sid}/status", json={"status": s}, headers=H)  # noqa: E731
    assert status("paused").status_code == 409  # a draft opens or closes
    assert status("open").status_code == 200
    started = token_of(join(client, study, "started"))
    h = {"Authorization": f"Bearer {started}"}
    state = client.get("/api/session", headers=h).json()
    client.post(f"/api/sessions/{state['session_id']}/consent", json={"agree": True}, headers=h)
    waiting = token_of(join(client, study, "waiting"))  # arrived, not yet consented
    assert status("paused").status_code == 200
    r = join(client, study, "new")
    assert r.status_code == 409 and "paused" in r.text
    assert client.get(f"/s/{waiting}").status_code == 409  # has not started: waits like any new arrival
    assert client.get(f"/s/{started}").status_code == 200  # a started session goes on
    run_through(client, started, "started")
    assert status("open").status_code == 200 and status("closed").status_code == 200
    assert status("open").status_code == 409  # closed for good
    assert client.post(f"/api/studies/{sid}/sessions", json={"count": 1}, headers=H).status_code == 409
    trials = export(client, sid)
    assert set(trials["participant"]) == {"P002"}  # the pilot left out
    assert export(client, sid, pilot="true")["participant"].nunique() == 2


def test_a_pilot_and_a_preview_leave_the_analysis_export_unchanged(client, tmp_path):
    study = make_study(client, questionnaires=[{"name": "end", "items": [{"id": "a", "text": "A?"}], "when": "end"}])
    sid = study["id"]
    run_through(client, token_of(join(client, study, "real")), "real")
    before = export(client, sid).drop(columns=["committed_at"])
    before_reports = export(client, sid, "reports")
    (pilot,) = client.post(f"/api/studies/{sid}/sessions", json={"count": 1, "pilot": True}, headers=H).json()
    run_through(client, pilot["token"], "p")
    rows = database_rows(tmp_path / "link.sqlite")
    preview = client.post(f"/api/studies/{sid}/preview", headers=H).json()
    token = urlsplit(preview["link"]).path.rsplit("/", 1)[-1]
    assert client.get(urlsplit(preview["link"]).path).status_code == 200  # the participant's page
    st = run_through(client, token, "v")
    h = {"Authorization": f"Bearer {token}"}
    assert st["preview"] and st["trials_done"] == 2 and st["questionnaire"]["name"] == "end"
    body = {"questionnaire": "end", "after_trial": 2, "answers": {"a": 4}}
    assert client.post(f"/api/sessions/{st['session_id']}/questionnaires", json=body, headers=h).json()["state"]["ended"]
    ev = {"events": [{"type": "outcome_shown", "trial": 2}], "batch": "b1"}
    assert client.post(f"/api/sessions/{st['session_id']}/events", json=ev, headers=h).status_code == 200
    assert database_rows(tmp_path / "link.sqlite") == rows  # no row of the preview in the study's database
    pd.testing.assert_frame_equal(export(client, sid).drop(columns=["committed_at"]), before)
    pd.testing.assert_frame_equal(export(client, sid, "reports"), before_reports)
    assert len(export(client, sid, "sessions")) == 1
    assert set(export(client, sid, pilot="true")["participant"]) == {"P001", pilot["participant"]}
    dash = client.get(f"/api/studies/{sid}/dashboard", headers=H).json()
    assert [r["role"] for r in dash["participants"]] == ["participant", "pilot"]  # the preview is not listed
    assert dash["study"]["participants"] == 1


def test_previews_beyond_the_kept_number_are_forgotten(client, monkeypatch):
    from trustseek.server import preview as previews

    monkeypatch.setattr(previews, "MAX_PREVIEWS", 2)
    study = make_study(client)
    links = [client.post(f"/api/studies/{study['id']}/preview", headers=H).json() for _ in range(3)]
    tokens = [urlsplit(x["link"]).path.rsplit("/", 1)[-1] for x in links]
    gone = client.get("/api/session", headers={"Authorization": f"Bearer {tokens[0]}"})
    assert gone.status_code == 401, gone.text  # the oldest is forgotten
    assert client.get("/api/session", headers={"Authorization": f"Bearer {tokens[2]}"}).json()["preview"]


def test_a_revoked_link_gets_a_page_and_its_session_takes_nothing(client):
    study = make_study(client)
    (link,) = client.post(f"/api/studies/{study['id']}/sessions", json={"count": 1}, headers=H).json()
    assert client.get(urlsplit(link["link"]).path).status_code == 200
    r = client.post(f"/api/studies/{study['id']}/sessions/{link['session_id']}/revoke", headers=H)
    assert r.status_code == 200, r.text
    page = client.get(urlsplit(link["link"]).path)
    assert page.status_code == 410 and "revoked" in page.text
    h = {"Authorization": f"Bearer {link['token']}"}
    assert client.post(f"/api/sessions/{link['session_id']}/consent", json={"agree": True}, headers=h).status_code == 410
    assert client.get("/api/session", headers=h).status_code == 410
    progress = client.get(f"/api/studies/{study['id']}", headers=H).json()["progress"]
    assert (progress["revoked"], progress["new"]) == (1, 0)  # counted apart, not as a participant still to start


def test_the_last_outcome_shown_is_stored_after_the_end(client):
    study = make_study(client)
    token = token_of(join(client, study, "z"))
    st = run_through(client, token, "z")
    h = {"Authorization": f"Bearer {token}"}
    ev = {"events": [{"type": "outcome_shown", "trial": st["trials_done"], "data": {"outcome": "success"}}]}
    r = client.post(f"/api/sessions/{st['session_id']}/events", json=ev, headers=h)
    assert r.status_code == 200, r.text
    assert "outcome_shown" in set(export(client, study["id"], "events")["type"])


def test_the_default_practice_has_one_asked_trial_labelled_practice(client):
    study = make_study(client, practice={"trials": ["low", "high"]})
    token = token_of(join(client, study, "practice"))
    h = {"Authorization": f"Bearer {token}"}
    sid = client.get("/api/session", headers=h).json()["session_id"]
    st = client.post(f"/api/sessions/{sid}/consent", json={"agree": True}, headers=h).json()
    seen = []
    while st["current"] and st["current"]["practice"]:
        cur = st["current"]
        seen.append(cur["robot_action"])
        human = "intervene" if cur["robot_action"] == "ask" else "rely"
        body = {"trial": cur["trial"], "submission_id": f"s{cur['trial']}", "human_action": human}
        st = client.post(f"/api/sessions/{sid}/trials", json=body, headers=h).json()["state"]
    assert seen == ["autonomous", "ask"]  # the never-ask practice policy, and the last practice trial asks
    none = make_study(client, practice={"trials": ["low"], "asks": []})
    assert none["id"]
    bad = client.post(
        "/api/studies", json={"name": "x", "blocks": BLOCKS, "practice": {"trials": ["low"], "asks": [2]}}, headers=H
    )
    assert bad.status_code == 422 and "practice.asks" in bad.text


def test_two_tabs_of_one_panel_id_store_every_outcome_shown(client):
    """Two tabs of one session take the trials in turns (each trial is committed by one tab, the
    other's submission refused); the tab that committed trial 3 posts its outcome_shown late,
    after the other tab committed trial 4 and answered the end questionnaire: it is stored."""
    study = make_study(client, questionnaires=[{"name": "end", "items": [{"id": "a", "text": "A?"}], "when": "end"}])
    token = token_of(join(client, study, "two-tabs"))
    assert token_of(join(client, study, "two-tabs")) == token  # the second tab resumes the same session
    h = {"Authorization": f"Bearer {token}"}
    sid = client.get("/api/session", headers=h).json()["session_id"]
    client.post(f"/api/sessions/{sid}/consent", json={"agree": True, "panel": {"PROLIFIC_PID": "two-tabs"}}, headers=h)

    def submit(tab: str, n: int) -> int:
        body = {"trial": n, "submission_id": f"{tab}-{n}", "human_action": "rely"}
        return client.post(f"/api/sessions/{sid}/trials", json=body, headers=h).status_code

    def shown(n: int) -> int:
        ev = {"events": [{"type": "outcome_shown", "trial": n, "data": {"tab": n}}], "batch": f"shown-{n}"}
        return client.post(f"/api/sessions/{sid}/events", json=ev, headers=h).status_code

    assert client.get(f"/api/sessions/{sid}/state", headers=h).json()["trials_total"] == 2
    assert (submit("a", 1), submit("b", 1)) == (200, 409)  # tab a commits trial 1; b follows the server
    assert (submit("b", 2), submit("a", 2)) == (200, 409)  # b commits the last trial ...
    body = {"questionnaire": "end", "after_trial": 2, "answers": {"a": 3}}
    assert client.post(f"/api/sessions/{sid}/questionnaires", json=body, headers=h).json()["state"]["ended"]
    assert shown(2) == 200
    assert shown(1) == 200  # tab a's outcome of trial 1, delayed: stored after the end
    assert shown(1) == 200  # a retry of that batch: stored once
    other = {"events": [{"type": "click", "trial": 2}], "batch": "other"}
    assert client.post(f"/api/sessions/{sid}/events", json=other, headers=h).status_code == 409  # nothing else
    future = {"events": [{"type": "outcome_shown", "trial": 3}], "batch": "future"}
    assert client.post(f"/api/sessions/{sid}/events", json=future, headers=h).status_code == 409  # no such trial
    events = export(client, study["id"], "events")
    assert sorted(events[events["type"] == "outcome_shown"]["trial"]) == [1, 2]
