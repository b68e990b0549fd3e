"""Checks shared by the SQLite and PostgreSQL server tests."""

from __future__ import annotations

import io
import signal
import sqlite3
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import closing

import httpx
import pandas as pd
import pytest

from trustseek.client import Client
from trustseek.data.trials import read_trials
from trustseek.testing.servers import ThreadServer, free_port, serve_process
from trustseek.vocab import ACTIONS


def database_rows(path) -> dict[str, list[str]]:
    """Every row of every table of a SQLite database file (each as its repr, sorted)."""
    with closing(sqlite3.connect(path)) as con:
        names = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
        return {n: sorted(map(repr, con.execute(f'SELECT * FROM "{n}"'))) for n in names}


def check_concurrent_duplicate_submissions(db_url: str, token: str) -> None:
    """Eight simultaneous submissions of one trial over real HTTP: one trial is stored,
    repeats of its submission id are answered as duplicates, other ids are refused (409)."""
    with ThreadServer(db_url, token) as url:
        c = Client(url, token)
        st = c.create_study({"name": "conc", "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 3}}}]})
        s = c.create_sessions(st["id"])[0]
        ph = {"Authorization": f"Bearer {s['token']}"}
        base = f"{url}/api/sessions/{s['session_id']}"
        httpx.post(f"{base}/consent", json={"agree": True}, headers=ph).raise_for_status()

        def post(i, n, same):
            body = {"trial": n, "submission_id": "same" if same else f"id-{i}", "human_action": "rely"}
            return httpx.post(f"{base}/trials", json=body, headers=ph, timeout=30)

        with ThreadPoolExecutor(8) as ex:
            same = list(ex.map(lambda i: post(i, 1, True), range(8)))
            other = list(ex.map(lambda i: post(i, 2, False), range(8)))
        assert [r.status_code for r in same] == [200] * 8
        assert sorted(r.json()["duplicate"] for r in same) == [False] + [True] * 7
        assert sorted(r.status_code for r in other) == [200] + [409] * 7
        frame = read_trials(pd.read_csv(io.BytesIO(c.export(st["id"]))))
        c.close()
    assert frame["trial"].tolist() == [1, 2]


POLICY_KINDS = [
    {"kind": "trust-agnostic"},
    {"kind": "randomized", "p_ask": {"low": 0.1, "high": 0.4}},
    {"kind": "always-ask"},
    {"kind": "never-ask"},
]


class Restartable:
    """A ``trustseek serve`` process on a fixed port that can be killed and started again."""

    def __init__(self, db_url: str, token: str):
        self.db_url, self.token, self.port, self.procs = db_url, token, free_port(), []
        self.url = f"http://127.0.0.1:{self.port}"

    def start(self):
        self.procs.append(serve_process(self.db_url, self.token, self.port))

    def kill(self):
        p = self.procs[-1]
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=10)

    def close(self):
        for p in self.procs:
            if p.poll() is None:
                p.kill()
            p.wait(timeout=10)


def _open(url: str, token: str, policy: dict) -> dict:
    r = httpx.post(
        f"{url}/api/deploy/sessions", json={"policy": policy}, headers={"Authorization": f"Bearer {token}"}, timeout=60
    )
    assert r.status_code == 201, r.text
    return r.json()


def _decide(url: str, s: dict, trial: int, complexity: str = "high") -> httpx.Response:
    return httpx.post(
        f"{url}/api/deploy/sessions/{s['session_id']}/decide",
        json={"trial": trial, "complexity": complexity},
        headers={"Authorization": f"Bearer {s['token']}"},
        timeout=30,
    )


def check_policies_decide_after_restart(db_url: str, token: str, rewrite=None) -> None:
    """Deploy sessions of every non-trust-aware policy kind decide, get killed with their
    server (SIGKILL), and decide and observe again in a new server process on the same
    database; ``rewrite()`` runs on the database while no server runs."""
    srv = Restartable(db_url, token)
    try:
        srv.start()
        sessions = [_open(srv.url, token, p) for p in POLICY_KINDS]
        for s in sessions:
            assert _decide(srv.url, s, 1).status_code == 200
        srv.kill()
        if rewrite is not None:
            rewrite()
        srv.start()
        for s, p in zip(sessions, POLICY_KINDS, strict=True):
            again = _decide(srv.url, s, 1)  # the stored decision
            assert again.status_code == 200, (p["kind"], again.text)
            assert again.json()["committed"] is False
            obs = httpx.post(
                f"{srv.url}/api/deploy/sessions/{s['session_id']}/observe",
                json={"trial": 1, "human_action": "intervene"},
                headers={"Authorization": f"Bearer {s['token']}"},
                timeout=30,
            )
            assert obs.status_code == 200, (p["kind"], obs.text)
            nxt = _decide(srv.url, s, 2, "low")  # a new decision: the policy is loaded from the database
            assert nxt.status_code == 200, (p["kind"], nxt.text)
    finally:
        srv.close()


def deploy_step(robot, pol, upd, task, b, cx, human, outcome):
    """One trial of deploy session ``robot`` checked against policy ``pol`` and belief updater
    ``upd`` at belief ``b``: the human's action and the outcome (None: the usual ones); returns
    the belief after it, and the action and outcome observed."""
    a = robot.decide(cx)
    c = task.complexity_index(cx)
    assert a == ACTIONS[pol.action(b, c)]
    if a == "ask":
        human, outcome, e = None, None, task.ask_experience[c]
    else:
        human = human or "rely"
        outcome = outcome or ("success" if human == "rely" else None)
        e = 0 if human == "intervene" or outcome == "failure" else 1
    belief = robot.observe(human_action=human, outcome=outcome)
    b = upd.update(b, c, ACTIONS.index(a), 0 if a == "ask" or human == "intervene" else 1, e)
    assert belief == pytest.approx(b[1], abs=1e-12)
    return b, human, outcome


def api_ids(client, token: str) -> dict[str, str]:
    """A study with a participant session, and a deploy session, made through ``client`` (a
    ``TestClient``): their ids and the sessions' tokens."""
    h = {"Authorization": f"Bearer {token}"}
    blocks = [{"name": "b", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "high"]}}]
    r = client.post("/api/studies", headers=h, json={"name": "s", "blocks": blocks})
    assert r.status_code == 201, r.text
    study = r.json()["id"]
    r = client.post(f"/api/studies/{study}/sessions", headers=h, json={"count": 1})
    assert r.status_code == 201, r.text
    part = r.json()[0]
    r = client.post("/api/deploy/sessions", headers=h, json={"model": "paper", "policy": {"kind": "never-ask"}})
    assert r.status_code == 201, r.text
    dep = r.json()
    return {
        "study": study,
        "participant": part["session_id"],
        "participant_token": part["token"],
        "deploy": dep["session_id"],
        "deploy_token": dep["token"],
    }


def case_headers(case, ids: dict[str, str], token: str) -> dict[str, str]:
    """A schemathesis ``case`` given the real ids of ``api_ids`` in its path; the headers of the
    token that may call it (the session's on session paths, else the experimenter's ``token``)."""
    path = case.operation.path
    if "{study_id}" in path:
        case.path_parameters["study_id"] = ids["study"]
    if "{session_id}" in path:
        kind = "deploy" if path.startswith("/api/deploy/") else "participant"
        case.path_parameters["session_id"] = ids[kind]
        token = ids[f"{kind}_token"]
    elif path == "/api/session":
        token = ids["participant_token"]
    return {"Authorization": f"Bearer {token}"}


def experimenter_view(client, study_id: str, session_id: str, headers: dict) -> dict:
    """The last committed trial of a session as the experimenter's dashboard shows it (with the
    belief and the experience, which the participant's page never receives)."""
    dash = client.get(f"/api/studies/{study_id}/dashboard", headers=headers)
    assert dash.status_code == 200, dash.text
    (row,) = [r for r in dash.json()["participants"] if r["session_id"] == session_id]
    return row["last"]


def check_two_processes_serve_one_robot(db_url: str, token: str) -> None:
    """A robot's requests reach two applications on one database (two worker processes),
    each of which answers from the session's state as it last knew it: when the other one has
    served the session in the meantime, the answer is still the one a single application
    gives (the same status and bytes, request by request), and the stored trials are those of
    a single application."""
    from fastapi.testclient import TestClient

    from trustseek.server.app import create_app

    policy = {"kind": "never-ask"}  # the robot acts: every observation below is one it allows
    rely = {"human_action": "rely", "outcome": "success"}
    steps = [
        ("a", "decide", {"trial": 1, "complexity": "high"}),
        ("a", "observe", {"trial": 1, **rely}),
        ("b", "decide", {"trial": 2, "complexity": "high"}),
        ("a", "decide", {"trial": 2, "complexity": "low"}),  # 409: decided by the other for "high"
        ("a", "decide", {"trial": 2, "complexity": "high"}),  # the other's decision
        ("b", "observe", {"trial": 2, **rely}),
        ("b", "decide", {"trial": 3, "complexity": "low"}),
        ("b", "observe", {"trial": 3, "human_action": "intervene"}),
        ("a", "observe", {"trial": 2, **rely}),  # a retry: the stored trial
        ("a", "observe", {"trial": 3, "human_action": "intervene"}),
        ("a", "decide", {"trial": 3, "complexity": "low"}),  # committed
        ("a", "decide", {"trial": 4, "complexity": "high"}),
        ("b", "decide", {"trial": 4, "complexity": "high"}),
        ("a", "observe", {"trial": 4, "human_action": "intervene"}),
        ("b", "decide", {"trial": 5, "complexity": "low"}),
        ("a", "observe", {"trial": 5, **rely}),
    ]

    def run(two: bool) -> tuple[list, dict]:
        apps = [create_app(db_url, token=token), create_app(db_url, token=token)]
        with TestClient(apps[0]) as a, TestClient(apps[1] if two else apps[0]) as b:
            r = a.post("/api/deploy/sessions", json={"policy": policy, "seed": 5}, headers={"Authorization": f"Bearer {token}"})
            assert r.status_code == 201, r.text
            sid, h = r.json()["session_id"], {"Authorization": f"Bearer {r.json()['token']}"}
            out = []
            for who, what, body in steps:
                res = (a if who == "a" else b).post(f"/api/deploy/sessions/{sid}/{what}", json=body, headers=h)
                out.append((res.status_code, res.content))
            state = a.get(f"/api/deploy/sessions/{sid}", headers=h).json()
        for app in apps:
            app.state.deploy_store.close()
        return out, state

    two, state = run(True)
    one, ref = run(False)
    for k, (x, y) in enumerate(zip(two, one, strict=True)):
        assert x == y, (k, steps[k], x, y)
    assert [s for s, _ in two] == [200, 200, 200, 409] + [200] * 12, two
    assert {k: v for k, v in state.items() if k not in ("session_id",)} == {k: v for k, v in ref.items() if k != "session_id"}
    assert [t["trial"] for t in state["trials"]] == [1, 2, 3, 4, 5]


def check_acknowledged_trials_survive(db: str, stored, token: str = "durability-token-0123") -> None:
    """Robots post to a ``trustseek serve`` process on database ``db``, which is killed while
    their requests are in flight; ``stored(session id)`` reads a session's trials back."""
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    proc = serve_process(db, token, port)
    try:
        admin = {"Authorization": f"Bearer {token}"}
        robots = []
        for i in range(4):
            r = httpx.post(
                f"{url}/api/deploy/sessions", json={"policy": {"kind": "trust-aware", "grid": 51}, "seed": i}, headers=admin
            )
            assert r.status_code == 201, r.text
            robots.append(r.json())
        acked: dict[str, list] = {r["session_id"]: [] for r in robots}  # (what, trial, answer)
        stop = threading.Event()

        def robot(info: dict) -> None:
            h = {"Authorization": f"Bearer {info['token']}"}
            base = f"{url}/api/deploy/sessions/{info['session_id']}"
            with httpx.Client(headers=h, timeout=5.0) as c:
                n = 1
                while not stop.is_set():
                    try:
                        d = c.post(f"{base}/decide", json={"trial": n, "complexity": "high" if n % 3 else "low"})
                        if d.status_code != 200:
                            return
                        acked[info["session_id"]].append(("decide", n, d.json()))
                        body = (
                            {"trial": n}
                            if d.json()["robot_action"] == "ask"
                            else {"trial": n, "human_action": "rely", "outcome": "success"}
                        )
                        o = c.post(f"{base}/observe", json=body)
                        if o.status_code != 200:
                            return
                        acked[info["session_id"]].append(("observe", n, o.json()))
                    except httpx.TransportError:  # the server is gone
                        return
                    n += 1

        threads = [threading.Thread(target=robot, args=(r,)) for r in robots]
        for t in threads:
            t.start()
        deadline = time.monotonic() + 30
        while sum(len(v) for v in acked.values()) < 60 and time.monotonic() < deadline:
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)  # requests in flight
        proc.wait(timeout=10)
        stop.set()
        for t in threads:
            t.join(timeout=10)
        assert sum(len(v) for v in acked.values()) >= 20
        proc = serve_process(db, token, port)
        for info in robots:
            sid = info["session_id"]
            rows = stored(sid)
            done = [n for what, n, _ in acked[sid] if what == "observe"]
            assert set(done) <= set(rows)  # every acknowledged trial is stored (once: the primary key)
            assert sorted(rows) == list(range(1, len(rows) + 1))
            for what, n, out in acked[sid]:
                if what == "observe":
                    t = out["trial"]
                    assert {k: rows[n][k] for k in t} == t
            last = acked[sid][-1] if acked[sid] else None
            if last is not None and last[0] == "decide" and last[1] not in rows:
                # an acknowledged decision without its observation: answered again as it was
                r = httpx.post(
                    f"{url}/api/deploy/sessions/{sid}/decide",
                    json={"trial": last[1], "complexity": last[2]["complexity"]},
                    headers={"Authorization": f"Bearer {info['token']}"},
                )
                assert r.status_code == 200 and r.json() == last[2]
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)
