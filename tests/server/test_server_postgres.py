"""The experiment server on a real PostgreSQL server.

A throwaway PostgreSQL cluster is created for this module (``initdb`` in a temporary
directory, ``pg_ctl start`` on a free loopback port with its socket in that directory) and
removed at the end.  The same migrations, studies, participant trials, duplicate submissions,
deploy API and export are run against it as against SQLite, and the export is checked against
what was posted and against an independent run of the solved policy and the Bayes filter.

Skipped only when the PostgreSQL server binaries are absent (``scripts/setup.sh`` installs
Debian's ``postgresql`` package when run as root).
"""

from __future__ import annotations

import asyncio
import io
import json

import numpy as np
import pandas as pd
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import create_engine, text

from server_checks import (
    check_acknowledged_trials_survive,
    check_concurrent_duplicate_submissions,
    check_policies_decide_after_restart,
    check_two_processes_serve_one_robot,
    deploy_step,
    experimenter_view,
)
from trustseek import BayesUpdate, paper_model, paper_task, solve
from trustseek.client import Client, DeploySession
from trustseek.data.trials import read_trials
from trustseek.server import create_app
from trustseek.testing.servers import TemporaryPostgres, postgres_binaries
from trustseek.vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS

TOKEN = "postgres-experimenter-secret"
H = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture(scope="module")
def pg_url(request):
    """A fresh PostgreSQL cluster on 127.0.0.1:<free port>, stopped and removed at the end."""
    if postgres_binaries() is None:
        pytest.skip(
            "PostgreSQL server binaries (initdb, pg_ctl) not found; scripts/setup.sh installs Debian's postgresql package as root"
        )
    cluster = TemporaryPostgres()
    request.addfinalizer(cluster.stop)
    return cluster.start()


@pytest.fixture(scope="module")
def app(pg_url):
    return create_app(pg_url, token=TOKEN)


@pytest.fixture
def pg_app(pg_url):
    """An application of the lean path's tests (``test_server_fastpath``'s token)."""
    from test_server_fastpath import TOKEN as FAST_TOKEN

    app = create_app(pg_url, token=FAST_TOKEN)
    yield app
    app.state.deploy_store.close()


def test_migrations_create_the_schema_and_rerun_as_a_no_op(pg_url, app):
    create_app(pg_url, token=TOKEN)  # a restart on the same database: nothing to do
    eng = create_engine(pg_url.replace("postgresql://", "postgresql+psycopg://"))
    with eng.connect() as c:
        assert c.execute(text("select version()")).scalar().startswith("PostgreSQL")
        assert c.execute(text("select version_num from alembic_version")).scalars().all() == ["0005"]
        tables = set(c.execute(text("select table_name from information_schema.tables where table_schema = 'public'")).scalars())
        uniques = set(
            c.execute(
                text("select constraint_name from information_schema.table_constraints where constraint_type = 'UNIQUE'")
            ).scalars()
        )
    eng.dispose()
    assert {"studies", "policies", "sessions", "trials", "reports", "events", "alembic_version"} <= tables
    assert {"uq_trial_session_number", "uq_session_study_participant", "uq_report_session_trial"} <= uniques


def test_study_with_a_trust_aware_block_round_trips_through_postgresql(pg_url, app):
    """Participant trials under a live trust-aware policy: the actions and stored beliefs equal
    an independent run of the solved policy and the Bayes filter; a repeated submission is
    answered from the database; the export holds exactly the posted trials and is a valid
    canonical trial log."""
    sched = ["high", "high", "low", "high", "high", "low"]
    humans = ["intervene", "rely", "rely", "intervene", "rely", "rely"]
    with TestClient(app) as client:
        r = client.post(
            "/api/studies",
            headers=H,
            json={
                "name": "pg",
                "self_report": "block",
                "blocks": [
                    {"name": "aware", "policy": {"kind": "trust-aware", "grid": 401}, "schedule": {"trials": sched}},
                    {"name": "never", "policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 1, "high": 1}}},
                ],
            },
        )
        assert r.status_code == 201, r.text
        st = r.json()
        (info,) = client.post(f"/api/studies/{st['id']}/sessions", json={"participants": ["P-pg"]}, headers=H).json()
        sid, ph = info["session_id"], {"Authorization": f"Bearer {info['token']}"}
        base = f"/api/sessions/{sid}"
        assert (
            client.post(
                f"{base}/consent", json={"agree": True, "events": [{"t": 5.0, "type": "consent"}]}, headers=ph
            ).status_code
            == 200
        )

        model, task = paper_model(), paper_task()
        pol, upd = solve(model, task, belief_update="bayes", grid=401), BayesUpdate(model)
        b = model.initial.copy()
        posted = []
        for n in range(1, len(sched) + 3):
            cur = client.get(f"{base}/state", headers=ph).json()["current"]
            assert cur["trial"] == n
            c = task.complexity_index(cur["complexity"])
            if n <= len(sched):
                assert (cur["block"], cur["complexity"], cur["robot_action"]) == (0, sched[n - 1], ACTIONS[pol.action(b, c)])
                human = "intervene" if cur["robot_action"] == "ask" else humans[n - 1]
            else:
                assert (cur["block"], cur["robot_action"]) == (1, "autonomous")
                human = "rely"
            body = {
                "trial": n,
                "submission_id": f"sub-{n}",
                "human_action": human,
                "effort_ms": 100.0 * n,
                "events": [{"t": 1000.0 + n, "type": "trial-end", "data": {"n": n}}],
            }
            res = client.post(f"{base}/trials", json=body, headers=ph)
            assert res.status_code == 200, res.text
            assert res.json()["duplicate"] is False and "belief" not in res.json()["trial"]
            t = experimenter_view(client, st["id"], sid, H)
            if n <= len(sched):
                assert t["belief"] == pytest.approx(b[1], abs=1e-12)
                b = upd.update(
                    b, c, ACTIONS.index(cur["robot_action"]), HUMAN_ACTIONS.index(human), EXPERIENCES.index(t["experience"])
                )
                assert t["belief_after"] == pytest.approx(b[1], abs=1e-12)
            posted.append(t)
            if n == 2:  # the same submission again: answered from the database, nothing stored twice
                again = client.post(f"{base}/trials", json=body, headers=ph)
                assert again.status_code == 200 and again.json()["duplicate"] is True
                assert again.json()["trial"] == res.json()["trial"]
                other = client.post(f"{base}/trials", json={**body, "submission_id": "another"}, headers=ph)
                assert other.status_code == 409 and "already committed" in other.text
            if n == len(sched):  # end of the first block: a self-report is due
                assert res.json()["state"]["report_due"] == n
                rep = client.post(f"{base}/reports", json={"after_trial": n, "value": 72.5}, headers=ph)
                assert rep.status_code == 200 and rep.json()["state"]["report_due"] is None
        state = client.get(f"{base}/state", headers=ph).json()
        assert state["status"] == "done" and state["trials_done"] == len(posted)
        assert state["score"] == pytest.approx(sum(t["reward"] for t in posted))
        assert any(t["robot_action"] == "ask" for t in posted)  # the policy asked after interventions

        dash = client.get(f"/api/studies/{st['id']}/dashboard", headers=H).json()
        (row,) = dash["participants"]
        assert row["trials_done"] == len(posted) and row["last"]["trial"] == len(posted) and row["last_self_report"] == 72.5

        csv = client.get(f"/api/studies/{st['id']}/export", params={"format": "csv"}, headers=H)
        parquet = client.get(f"/api/studies/{st['id']}/export", params={"format": "parquet"}, headers=H)
        events = client.get(f"/api/studies/{st['id']}/export", params={"table": "events"}, headers=H)
    for frame in (pd.read_csv(io.BytesIO(csv.content)), pd.read_parquet(io.BytesIO(parquet.content))):
        canon = read_trials(frame)
        assert canon["participant"].tolist() == ["P-pg"] * len(posted)
        assert canon["trial"].tolist() == [t["trial"] for t in posted]
        for col in ("complexity", "robot_action", "human_action", "experience"):
            assert canon[col].tolist() == [t[col] for t in posted], col
        assert frame["reward"].tolist() == [t["reward"] for t in posted]
        assert np.allclose(frame["belief"].to_numpy(float), [t["belief"] for t in posted], atol=1e-12)
        assert frame["effort_ms"].tolist() == [t["effort_ms"] for t in posted]
    ev = pd.read_csv(io.BytesIO(events.content))
    assert ev["type"].tolist() == ["consent"] + ["trial-end"] * len(posted)
    assert ev["trial"].tolist()[1:] == [t["trial"] for t in posted]


def test_concurrent_duplicate_submissions_store_one_trial(pg_url, app):
    """Simultaneous submissions contend for PostgreSQL's row lock: exactly one trial is stored."""
    check_concurrent_duplicate_submissions(pg_url, TOKEN)


def test_deploy_api_on_postgresql_resumes_after_a_restart(pg_url, app):
    """The decision API: actions and beliefs follow the solved policy and the Bayes filter;
    retries are idempotent; a new server process on the same database continues the session."""
    model, task = paper_model(), paper_task()
    pol, upd = solve(model, task, grid=401), BayesUpdate(model)
    b = model.initial.copy()
    steps = [("high", "intervene", None), ("high", None, None), ("low", "rely", "success"), ("high", "rely", "failure")]
    with TestClient(app) as http:
        robot = Client("http://test", TOKEN, http=http).open_deploy(model="paper", policy={"kind": "trust-aware", "grid": 401})
        for cx, human, outcome in steps[:3]:
            b, _, _ = deploy_step(robot, pol, upd, task, b, cx, human, outcome)
        assert robot.decide("low", trial=3) == robot.state()["trials"][2]["robot_action"]  # retry of a committed trial
        first = robot.state()
        sid, token = robot.session_id, robot.token
    with TestClient(create_app(pg_url, token=TOKEN)) as http2:  # a new server on the same database
        robot2 = DeploySession(http2, {"session_id": sid, "token": token})
        robot2.trial = robot2.state()["trials_done"]
        assert robot2.trial == first["trials_done"] == 3
        cx, human, outcome = steps[3]
        b, human, outcome = deploy_step(robot2, pol, upd, task, b, cx, human, outcome)
        again = robot2.observe(human_action=human, outcome=outcome, trial=4)  # a repeated observation
        assert again == pytest.approx(b[1], abs=1e-12)
        state = robot2.state()
    assert [t["trial"] for t in state["trials"]] == [1, 2, 3, 4]
    assert state["trials"][:3] == first["trials"]
    assert state["belief"] == pytest.approx(b[1], abs=1e-12)


def test_every_policy_kind_decides_after_a_server_process_restart(pg_url, app):
    """Deploy sessions of the trust-agnostic, randomized, always-ask and never-ask policies keep
    deciding after their ``trustseek serve`` process is killed and a new one starts."""
    check_policies_decide_after_restart(pg_url, TOKEN)


def test_each_decision_and_observation_is_one_statement_on_postgresql(pg_app, monkeypatch):
    """After a session is opened, the lean path answers each new decision and observation with
    one statement sent to PostgreSQL (a write conditional on the session's row, committed by
    itself), and with the full application's bytes; repeats are answered from the database."""
    import psycopg
    from test_server_fastpath import Counting, open_session, post

    sent = []
    for cls in (psycopg.Cursor, psycopg.AsyncCursor):
        monkeypatch.setattr(cls, "execute", _counted(cls.execute, sent))
    lean, full = open_session(pg_app), open_session(pg_app)
    counting = Counting(pg_app)
    for n in range(1, 6):
        d = {"trial": n, "complexity": "high" if n % 2 else "low"}
        sent.clear()
        a = post(pg_app, False, *lean, "decide", d)
        assert len(sent) == 1 and sent[0].startswith("UPDATE sessions"), sent
        assert a == post(pg_app, True, *full, "decide", d) and a[0] == 200
        o = (
            {"trial": n}
            if json.loads(a[2])["robot_action"] == "ask"
            else {"trial": n, "human_action": "rely", "outcome": "success"}
        )
        sent.clear()
        a = post(pg_app, False, *lean, "observe", o)
        assert len(sent) == 1 and sent[0].startswith("WITH advanced AS (UPDATE sessions"), sent
        assert a == post(pg_app, True, *full, "observe", o) and a[0] == 200
        sent.clear()
        again = post(pg_app, False, *lean, "observe", o)  # a repeat: read in a transaction
        assert json.loads(again[2])["duplicate"] is True and len(sent) > 1
    assert counting.calls == 0


def _counted(execute, sent: list):
    if asyncio.iscoroutinefunction(execute):

        async def counted_async(self, query, *args, **kwargs):
            sent.append(str(query))
            return await execute(self, query, *args, **kwargs)

        return counted_async

    def counted(self, query, *args, **kwargs):
        sent.append(str(query))
        return execute(self, query, *args, **kwargs)

    return counted


def test_two_server_processes_answer_a_robot_as_one_on_postgresql(pg_url):
    check_two_processes_serve_one_robot(pg_url, TOKEN)


def test_a_broken_connection_of_the_conditional_writes_is_replaced(pg_app):
    from test_server_fastpath import open_session, post

    sid, token = open_session(pg_app)
    assert post(pg_app, False, sid, token, "decide", {"trial": 1, "complexity": "low"})[0] == 200
    store = pg_app.state.deploy_store
    assert len(store._idle) == 1
    store._idle[0].pgconn.finish()  # the connection breaks
    status, _, out = post(pg_app, False, sid, token, "observe", {"trial": 1, "human_action": "intervene"})
    assert status == 200, out
    assert json.loads(out)["trial"]["trial"] == 1
    assert post(pg_app, False, sid, token, "decide", {"trial": 2, "complexity": "high"})[0] == 200
    assert len(store._idle) == 1 and not store._idle[0].closed  # a new one


def test_requests_wait_for_a_connection_of_the_conditional_writes(pg_app, monkeypatch):
    """More robots at once than the connections of the conditional writes: the requests wait
    for one (no more are opened) and are all answered by a conditional write."""
    from test_server_concurrency import post as post_async
    from test_server_fastpath import open_session

    from trustseek.server.deploy import store as store_module

    monkeypatch.setattr(store_module, "ASYNC_CONNECTIONS", 2)
    robots = [open_session(pg_app, seed=i) for i in range(12)]
    store = pg_app.state.deploy_store

    def no_transaction():
        raise AssertionError("a request ran in a transaction")

    monkeypatch.setattr(store, "transaction", no_transaction)
    waited = []
    checkout = store._checkout

    async def counted_checkout():
        waited.append(len(store._waiters))
        return await checkout()

    monkeypatch.setattr(store, "_checkout", counted_checkout)

    async def decide_all():
        body = {"trial": 1, "complexity": "low"}
        return await asyncio.gather(*(post_async(pg_app, f"/api/deploy/sessions/{sid}/decide", body, tok) for sid, tok in robots))

    out = asyncio.run(decide_all())
    assert [status for status, _ in out] == [200] * 12
    assert max(waited) > 0  # requests waited
    assert store._opened == 2 and len(store._idle) == 2 and not store._waiters
    assert all(store.known.get(sid).pending_trial == 1 for sid, _ in robots)


def test_acknowledged_trials_survive_a_killed_server_on_postgresql(pg_url):
    """``tests/server/test_server_durability.py`` on PostgreSQL: acknowledged decisions and trials are
    committed (one statement each, committed by itself) before the answer."""
    engine = create_engine(pg_url.replace("postgresql://", "postgresql+psycopg://"))

    def stored(sid: str) -> dict[int, dict]:
        with engine.connect() as c:
            rows = c.execute(text("SELECT * FROM trials WHERE session_id = :sid"), {"sid": sid}).mappings()
            return {r["trial"]: dict(r) for r in rows}

    try:
        check_acknowledged_trials_survive(pg_url, stored, TOKEN)
    finally:
        engine.dispose()
