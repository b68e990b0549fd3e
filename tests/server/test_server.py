"""Experiment server: studies, live policy, trial logic, integrity, export (in-process client)."""

from __future__ import annotations

import io
import json

import numpy as np
import pandas as pd
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import create_engine, text

from server_checks import check_concurrent_duplicate_submissions, deploy_step, experimenter_view
from trustseek import BayesUpdate, paper_model, paper_task, solve
from trustseek.client import Client, ServerError
from trustseek.server import create_app
from trustseek.vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS

TOKEN = "experimenter-secret"
H = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture
def db_url(tmp_path):
    return f"sqlite:///{tmp_path / 'study.sqlite'}"


@pytest.fixture
def client(db_url):
    with TestClient(create_app(db_url, token=TOKEN)) as c:
        yield c


def study(client, **over):
    body = {
        "name": "test",
        "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 3, "high": 2}}}],
    }
    body.update(over)
    r = client.post("/api/studies", json=body, headers=H)
    assert r.status_code == 201, r.text
    return r.json()


def participant(client, study_id, **body):
    r = client.post(f"/api/studies/{study_id}/sessions", json=body or {"count": 1}, headers=H)
    assert r.status_code == 201, r.text
    s = r.json()[0]
    return s["session_id"], {"Authorization": f"Bearer {s['token']}"}


def start(client, sid, ph):
    r = client.post(f"/api/sessions/{sid}/consent", json={"agree": True, "events": [{"t": 1.0, "type": "consent"}]}, headers=ph)
    assert r.status_code == 200, r.text
    return r.json()


def submit(client, sid, ph, n, human, sub=None, **extra):
    return client.post(
        f"/api/sessions/{sid}/trials",
        json={"trial": n, "submission_id": sub or f"s{n}", "human_action": human, **extra},
        headers=ph,
    )


def export(client, study_id, table="trials", fmt="csv"):
    r = client.get(f"/api/studies/{study_id}/export", params={"table": table, "format": fmt}, headers=H)
    assert r.status_code == 200, r.text
    return pd.read_csv(io.BytesIO(r.content)) if fmt == "csv" else pd.read_parquet(io.BytesIO(r.content))


# --------------------------------------------------------------------------- study configuration


def test_openapi_is_served(client):
    spec = client.get("/openapi.json").json()
    for path in (
        "/api/studies",
        "/api/studies/{study_id}/export",
        "/api/sessions/{session_id}/trials",
        "/api/deploy/sessions/{session_id}/decide",
    ):
        assert path in spec["paths"]
    # every body's schema under its own name: two classes of one name were served as
    # 'trustseek__server__schemas__QuizIn', the name a generated client then carries
    assert not [name for name in spec["components"]["schemas"] if "__" in name]


@pytest.mark.parametrize(
    "body, status, words",
    [
        ({"task": "nonsense"}, 422, ["unknown task preset"]),
        ({"blocks": []}, 422, ["blocks"]),
        (
            {"blocks": [{"policy": {"kind": "sometimes"}, "schedule": {"counts": {"low": 1}}}]},
            400,
            ["blocks[0].policy.kind", "sometimes"],
        ),
        (
            {"blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "medium"]}}]},
            400,
            ["blocks[0].schedule", "medium"],
        ),
        (
            {"blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 1}, "trials": ["low"]}}]},
            422,
            ["exactly one"],
        ),
        (
            {
                "blocks": [
                    {"policy": {"kind": "randomized", "p_ask": {"low": 2, "high": 0.1}}, "schedule": {"counts": {"low": 1}}}
                ]
            },
            400,
            ["p_ask"],
        ),
        ({"self_report": "sometimes"}, 422, ["self_report"]),
    ],
)
def test_study_validation_gives_clear_4xx(client, body, status, words):
    base = {"name": "bad", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 1}}}]}
    base.update(body)
    r = client.post("/api/studies", json=base, headers=H)
    assert r.status_code == status, r.text
    for w in words:
        assert w in r.text


def test_schedules_and_counterbalancing(client):
    st = study(
        client,
        blocks=[
            {"name": "A", "policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 4, "high": 3}}},
            {"name": "B", "policy": {"kind": "always-ask"}, "schedule": {"trials": ["high", "low", "high"]}},
        ],
        counterbalance="rotate",
    )
    r = client.post(f"/api/studies/{st['id']}/sessions", json={"participants": ["x", "y", "z"]}, headers=H).json()
    assert [s["block_order"] for s in r] == [["A", "B"], ["B", "A"], ["A", "B"]]
    with Client("http://test", TOKEN, http=client) as c:
        cfg = c.dashboard(st["id"])
    assert [p["participant"] for p in cfg["participants"]] == ["x", "y", "z"]
    # each participant's block A has exactly 4 low and 3 high trials; block B the fixed list
    sid, token = r[1]["session_id"], r[1]["token"]
    ph = {"Authorization": f"Bearer {token}"}
    start(client, sid, ph)
    seen = []
    for n in range(1, 11):
        cur = client.get(f"/api/sessions/{sid}/state", headers=ph).json()["current"]
        seen.append((cur["block"], cur["complexity"], cur["robot_action"]))
        human = "intervene" if cur["robot_action"] == "ask" else "rely"
        assert submit(client, sid, ph, n, human).status_code == 200
    assert [c for b, c, _ in seen[:3]] == ["high", "low", "high"] and all(b == 1 for b, _, _ in seen[:3])
    assert all(a == "ask" for _, _, a in seen[:3]) and all(a == "autonomous" for _, _, a in seen[3:])
    assert sorted(c for _, c, _ in seen[3:]) == ["high"] * 3 + ["low"] * 4
    assert client.get(f"/api/sessions/{sid}/state", headers=ph).json()["status"] == "done"


def test_duplicate_participant_id_is_refused(client):
    st = study(client)
    participant(client, st["id"], participants=["p1"])
    r = client.post(f"/api/studies/{st['id']}/sessions", json={"participants": ["p1"]}, headers=H)
    assert r.status_code == 409 and "p1" in r.text


# --------------------------------------------------------------------------- live policy


def test_trust_aware_policy_runs_live_with_the_exact_bayes_filter(client):
    """The server's actions and stored beliefs equal an independent run of the solved policy and
    the Bayes filter over the same events."""
    sched = ["high", "high", "low", "high", "high", "high", "low", "high"]
    st = study(client, blocks=[{"policy": {"kind": "trust-aware", "grid": 401}, "schedule": {"trials": sched}}])
    sid, ph = participant(client, st["id"])
    start(client, sid, ph)
    model, task = paper_model(), paper_task()
    pol = solve(model, task, belief_update="bayes", grid=401)
    upd = BayesUpdate(model)
    b = model.initial.copy()
    humans = ["intervene", "rely", "rely", "intervene", "rely", "rely", "rely", "intervene"]
    for n, (cx, human) in enumerate(zip(sched, humans, strict=True), start=1):
        cur = client.get(f"/api/sessions/{sid}/state", headers=ph).json()["current"]
        c = task.complexity_index(cx)
        expected = ACTIONS[pol.action(b, c)]
        assert (cur["trial"], cur["complexity"], cur["robot_action"]) == (n, cx, expected)
        if expected == "ask":
            human = "intervene"
        assert "belief" not in submit(client, sid, ph, n, human).json()["trial"]
        res = experimenter_view(client, st["id"], sid, H)
        assert res["trial"] == n and res["belief"] == pytest.approx(b[1], abs=1e-12)
        o = HUMAN_ACTIONS.index(human)
        b = upd.update(b, c, ACTIONS.index(expected), o, EXPERIENCES.index(res["experience"]))
        assert res["belief_after"] == pytest.approx(b[1], abs=1e-12)
    frame = export(client, st["id"])
    assert frame["robot_action"].tolist().count("ask") >= 1  # the policy did ask after interventions


def test_outcomes_experience_and_reward_follow_the_task(client):
    """Autonomous success is drawn with the task's probability; experience and reward follow
    Section III and eq. (1); the score is their sum."""
    st = study(
        client,
        blocks=[
            {"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 100, "high": 100}}},
            {"policy": {"kind": "always-ask"}, "schedule": {"counts": {"low": 2, "high": 2}}},
        ],
    )
    sid, ph = participant(client, st["id"])
    start(client, sid, ph)
    for n in range(1, 205):
        human = "intervene" if n in (5, 6) or n > 200 else "rely"
        r = submit(client, sid, ph, n, human)
        assert r.status_code == 200, r.text
    f = export(client, st["id"])
    assert f.columns[:6].tolist() == ["participant", "trial", "complexity", "robot_action", "human_action", "experience"]
    assert f["trial"].tolist() == list(range(1, 205))
    rely = f[(f.robot_action == "autonomous") & (f.human_action == "rely")]
    for cx, p in (("low", 0.97), ("high", 0.83)):
        rows = rely[rely.complexity == cx]
        k, m = int((rows.outcome == "success").sum()), len(rows)
        sd = np.sqrt(p * (1 - p) / m)
        assert abs(k / m - p) < 4.5 * sd, (cx, k, m)
    assert set(rely.outcome) <= {"success", "collision", "dropped"}
    assert (rely.experience == np.where(rely.outcome == "success", "reliable", "faulty")).all()
    assert (rely.reward == np.where(rely.outcome == "success", 2.0, -3.0)).all()
    inter = f[(f.robot_action == "autonomous") & (f.human_action == "intervene")]
    assert len(inter) == 2 and (inter.experience == "faulty").all() and (inter.reward == 0).all()
    ask = f[f.robot_action == "ask"]
    assert (ask.human_action == "intervene").all() and (ask.reward == 1.0).all()
    assert (ask.experience == np.where(ask.complexity == "high", "reliable", "faulty")).all()
    state = client.get(f"/api/sessions/{sid}/state", headers=ph).json()
    assert state["score"] == pytest.approx(f.reward.sum()) and state["status"] == "done"


# --------------------------------------------------------------------------- integrity


def test_a_consent_posted_again_stores_its_events_once(client):
    """A page retries its consent when the answer is lost (a 5xx, a dropped connection): the
    session stays started, and its consent event was stored a second time (seen in the crowd test)."""
    st = study(client)
    sid, ph = participant(client, st["id"])
    first, again = start(client, sid, ph), start(client, sid, ph)
    assert first["status"] == again["status"] == "running"
    assert export(client, st["id"], table="events")["type"].tolist() == ["consent"]


def test_submissions_are_validated_and_idempotent(client):
    st = study(client, blocks=[{"policy": {"kind": "always-ask"}, "schedule": {"trials": ["low", "high", "high"]}}])
    sid, ph = participant(client, st["id"])
    assert submit(client, sid, ph, 1, "intervene").status_code == 409  # no consent yet
    start(client, sid, ph)
    r = submit(client, sid, ph, 1, "rely")
    assert r.status_code == 400 and "asked" in r.text
    assert submit(client, sid, ph, 2, "intervene").status_code == 409  # not the current trial
    assert submit(client, sid, ph, 1, "wave").status_code == 422
    bad = client.post(
        f"/api/sessions/{sid}/trials", json={"trial": 1, "submission_id": "x y", "human_action": "intervene"}, headers=ph
    )
    assert bad.status_code == 422 and "submission_id" in bad.text
    first = submit(client, sid, ph, 1, "intervene", sub="abc", effort_ms=1234.5)
    assert first.status_code == 200 and first.json()["duplicate"] is False
    again = submit(client, sid, ph, 1, "intervene", sub="abc", effort_ms=1234.5)
    assert again.status_code == 200 and again.json()["duplicate"] is True
    assert again.json()["trial"] == first.json()["trial"]
    other = submit(client, sid, ph, 1, "intervene", sub="other")
    assert other.status_code == 409 and "already committed" in other.text
    f = export(client, st["id"])
    assert f["trial"].tolist() == [1] and f["effort_ms"].tolist() == [1234.5]
    assert client.get(f"/api/sessions/{sid}/state", headers=ph).json()["current"]["trial"] == 2


def test_self_reports_per_block(client, db_url):
    st = study(
        client,
        self_report="block",
        blocks=[
            {"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "low"]}},
            {"policy": {"kind": "never-ask"}, "schedule": {"trials": ["high"]}},
        ],
    )
    sid, ph = participant(client, st["id"])
    start(client, sid, ph)
    s = submit(client, sid, ph, 1, "rely").json()["state"]
    assert s["report_due"] is None
    s = submit(client, sid, ph, 2, "rely").json()["state"]
    assert s["report_due"] == 2
    assert client.post(f"/api/sessions/{sid}/reports", json={"after_trial": 2, "value": 101}, headers=ph).status_code == 422
    assert client.post(f"/api/sessions/{sid}/reports", json={"after_trial": 3, "value": 50}, headers=ph).status_code == 409
    r = client.post(f"/api/sessions/{sid}/reports", json={"after_trial": 2, "value": 64}, headers=ph)
    assert r.status_code == 200 and r.json()["state"]["report_due"] is None
    assert client.post(f"/api/sessions/{sid}/reports", json={"after_trial": 2, "value": 64}, headers=ph).json()["report"][
        "duplicate"
    ]
    assert client.post(f"/api/sessions/{sid}/reports", json={"after_trial": 2, "value": 10}, headers=ph).status_code == 409
    bad_page = {"t": 1, "type": "grasp", "page": "no spaces"}
    assert client.post(f"/api/sessions/{sid}/events", json={"events": [bad_page]}, headers=ph).status_code == 422
    submit(client, sid, ph, 3, "rely", events=[{"t": 1700000000000.5, "type": "grasp", "page": "4f2a", "data": {"by": "robot"}}])
    f = export(client, st["id"], fmt="parquet")
    assert f["self_report"].tolist()[:2] == [None, 64.0] or (np.isnan(f["self_report"][0]) and f["self_report"][1] == 64.0)
    ev = export(client, st["id"], table="events")
    assert ev["type"].tolist() == ["consent", "grasp"]
    assert ev["client_time"].tolist()[1] == 1700000000000.5 and json.loads(ev["data"][1]) == {"by": "robot"}
    assert ev["trial"].tolist()[1] == 3
    assert ev["page"].isna().tolist() == [True, False] and ev["page"][1] == "4f2a"  # the page load that sent it, if told
    later = client.post(f"/api/sessions/{sid}/events", json={"events": [{"t": 2, "type": "scene", "page": "9c"}]}, headers=ph)
    assert later.status_code == 200 and later.json()["stored"] == 1
    assert export(client, st["id"], table="sessions")["pages"].tolist() == [2]  # 4f2a and 9c (a reload, a second tab)
    # events that came without a page (stored before events named it): the count is unknown, not 0
    with create_engine(db_url).begin() as conn:
        conn.execute(text("update events set page = null"))
    assert export(client, st["id"], table="sessions")["pages"].isna().tolist() == [True]


def test_export_is_read_by_the_data_module_and_cli(client, db_url, tmp_path):
    from typer.testing import CliRunner

    from trustseek.cli import app
    from trustseek.data.trials import read_trials

    st = study(client)
    sid, ph = participant(client, st["id"])
    start(client, sid, ph)
    for n in range(1, 6):
        submit(client, sid, ph, n, "rely" if n != 2 else "intervene")
    out = tmp_path / "trials.csv"
    res = CliRunner().invoke(
        app, ["export", st["id"], "--db", db_url, "--out", str(out), "--events", str(tmp_path / "ev.parquet"), "--json"]
    )
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["trials"] == 5
    frame = read_trials(out)
    assert frame["trial"].tolist() == [1, 2, 3, 4, 5]
    assert frame["human_action"].tolist()[1] == "intervene"
    assert "belief" in frame.columns and "reward" in frame.columns


def test_migrations_run_once_and_are_idempotent(db_url, tmp_path):
    create_app(db_url, token=TOKEN)
    create_app(db_url, token=TOKEN)  # a restart: nothing to do, nothing lost
    eng = create_engine(db_url)
    with eng.connect() as c:
        assert c.execute(text("select version_num from alembic_version")).scalars().all() == ["0005"]
        tables = set(c.execute(text("select name from sqlite_master where type='table'")).scalars())
    assert {"studies", "sessions", "trials", "reports", "events"} <= tables


# --------------------------------------------------------------------------- deploy API


def test_deploy_api_through_the_client(client):
    c = Client("http://test", TOKEN, http=client)
    robot = c.open_deploy(model="paper", policy={"kind": "trust-aware", "grid": 401})
    model, task = paper_model(), paper_task()
    pol, upd = solve(model, task, grid=401), BayesUpdate(model)
    b = model.initial.copy()
    events = [
        ("high", "intervene", None),
        ("high", None, None),
        ("low", "rely", "success"),
        ("high", "rely", "failure"),
        ("high", None, None),
    ]
    for cx, human, outcome in events:
        b, _, _ = deploy_step(robot, pol, upd, task, b, cx, human, outcome)
    state = robot.state()
    assert [t["trial"] for t in state["trials"]] == [1, 2, 3, 4, 5]
    # idempotent retries, conflicts and validation
    assert robot.decide("high", trial=5) == state["trials"][4]["robot_action"]
    with pytest.raises(ServerError) as ei:
        robot.decide("low", trial=5)
    assert ei.value.status == 409
    with pytest.raises(ServerError) as ei:
        robot.decide("medium")
    assert ei.value.status == 400 and "complexity" in str(ei.value)
    with pytest.raises(ServerError) as ei:
        robot.observe("rely", "success")  # trial 6 not decided yet
    assert ei.value.status == 409
    robot.decide("low")
    with pytest.raises(ServerError) as ei:
        robot.observe("rely")  # outcome missing
    assert ei.value.status == 400 and "outcome" in str(ei.value)
    if robot.action == "autonomous":
        with pytest.raises(ServerError) as ei:
            robot.observe("intervene", "success")  # a takeover is not an autonomous success
        assert ei.value.status == 400 and "teleoperated" in str(ei.value)
    with pytest.raises(ServerError) as ei:
        c.open_deploy(policy={"kind": "psychic"})
    assert ei.value.status == 400


def test_pages_are_served_without_external_resources(client):
    from trustseek.server.app import STATIC

    if not (STATIC / "participant.html").exists():
        pytest.fail("front end not built: run scripts/setup.sh")
    for path in ("/dashboard", "/s/some-token"):
        r = client.get(path)
        assert r.status_code == 200
        assert "http://" not in r.text and "https://" not in r.text
    js = client.get("/static/app/participant.js")
    assert js.status_code == 200 and "https://" not in js.text.replace("https://github.com", "")


def test_concurrent_duplicate_submissions_store_one_trial(tmp_path):
    """Simultaneous duplicate submissions on SQLite: exactly one trial is stored."""
    check_concurrent_duplicate_submissions(f"sqlite:///{tmp_path / 'conc.sqlite'}", TOKEN)


def test_migrations_render_for_postgresql():
    """The same migrations produce PostgreSQL DDL (rendered offline, no server needed)."""
    from trustseek.server.db import offline_sql

    sql = offline_sql("postgresql://user:pw@localhost/study")
    for table in ("studies", "policies", "sessions", "trials", "reports", "events", "alembic_version"):
        assert f"CREATE TABLE {table}" in sql
    assert "CONSTRAINT uq_trial_session_number UNIQUE (session_id, trial)" in sql
    assert "id SERIAL NOT NULL" in sql and "JSON NOT NULL" in sql


def test_database_errors_are_one_clear_line_without_the_password():
    from trustseek.server.db import DatabaseError

    with pytest.raises(DatabaseError) as ei:
        create_app("postgresql://user:hunter2@127.0.0.1:1/study", token=TOKEN)
    (line,) = ei.value.lines()
    assert "hunter2" not in line and "cannot" in line


def test_self_reports_per_trial(client):
    st = study(
        client, self_report="trial", blocks=[{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "high", "low"]}}]
    )
    sid, ph = participant(client, st["id"])
    assert start(client, sid, ph)["report_due"] is None
    for n in (1, 2, 3):
        s = submit(client, sid, ph, n, "rely").json()["state"]
        assert s["report_due"] == n
        s = client.post(f"/api/sessions/{sid}/reports", json={"after_trial": n, "value": 10 * n}, headers=ph).json()["state"]
        assert s["report_due"] is None
    assert s["status"] == "done"
    assert export(client, st["id"])["self_report"].tolist() == [10.0, 20.0, 30.0]
    none = study(client)
    sid2, ph2 = participant(client, none["id"])
    start(client, sid2, ph2)
    submit(client, sid2, ph2, 1, "rely")
    r = client.post(f"/api/sessions/{sid2}/reports", json={"after_trial": 1, "value": 50}, headers=ph2)
    assert r.status_code == 409 and "no trust self-reports" in r.text


def test_client_reads_local_task_model_and_policy_files(client, tmp_path):
    """Files stay on the experimenter's side: the client sends their JSON.  The solved policy
    from a file behaves exactly as the one solved by the server."""
    from trustseek import paper_model, paper_task
    from trustseek import solve as solve_policy

    paper_task().save(tmp_path / "task.json")
    paper_model().save(tmp_path / "model.json")
    solve_policy(paper_model(), paper_task(), grid=301).save(tmp_path / "policy.json")
    (tmp_path / "study.json").write_text(
        json.dumps(
            {
                "name": "files",
                "task": str(tmp_path / "task.json"),
                "model": str(tmp_path / "model.json"),
                "blocks": [{"policy": str(tmp_path / "policy.json"), "schedule": {"trials": ["high"]}}],
            }
        )
    )
    c = Client("http://test", TOKEN, http=client)
    st = c.create_study(tmp_path / "study.json")
    assert st["blocks"][0]["policy"] == "trust-aware"
    assert st["blocks"][0]["thresholds"]["high"] == pytest.approx(
        solve_policy(paper_model(), paper_task(), grid=301).thresholds()["high"]
    )
    with pytest.raises(Exception) as ei:
        c.create_study({"name": "x", "task": str(tmp_path / "missing.json"), "blocks": []})
    assert "missing.json" in str(ei.value) and "not found" in str(ei.value)


def test_sqlite_checkpoints_run_in_the_background(tmp_path):
    """Committed trials reach the main database file without any request running a WAL
    checkpoint (the log stays far below the in-commit backstop): a background thread does it."""
    import sqlite3
    import time

    from trustseek.server.db import BACKSTOP_CHECKPOINT_PAGES

    path = tmp_path / "wal.sqlite"
    app = create_app(f"sqlite:///{path}", token=TOKEN)

    def in_main_file() -> int | None:  # read the main file alone, ignoring the log
        try:
            con = sqlite3.connect(f"file:{path}?immutable=1", uri=True)
            try:
                return con.execute("select count(*) from trials").fetchone()[0]
            finally:
                con.close()
        except sqlite3.DatabaseError:  # caught mid-checkpoint: look again
            return None

    with TestClient(app) as http:  # looked at while the server runs (stopping it closes the log)
        robot = Client("http://test", TOKEN, http=http).open_deploy(policy={"kind": "never-ask"})
        for _ in range(20):
            robot.decide("low")
            robot.observe("rely", "success")
        deadline = time.monotonic() + 30
        while in_main_file() != 20 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert in_main_file() == 20
        assert (path.parent / "wal.sqlite-wal").stat().st_size < BACKSTOP_CHECKPOINT_PAGES * 4096
    del app
