"""Checks shared by the SQLite and PostgreSQL server tests."""

from __future__ import annotations

import io
import signal
from concurrent.futures import ThreadPoolExecutor

import httpx
import pandas as pd

from trustseek.client import Client
from trustseek.data.trials import read_trials
from trustseek.testing.servers import ThreadServer, free_port, serve_process


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


def experimenter_view(client, study_id: str, session_id: str, headers: dict) -> dict:
    """The last committed trial of a session as the experimenter's dashboard shows it (with the
    belief and the experience, which the participant's page never receives)."""
    dash = client.get(f"/api/studies/{study_id}/dashboard", headers=headers)
    assert dash.status_code == 200, dash.text
    (row,) = [r for r in dash.json()["participants"] if r["session_id"] == session_id]
    return row["last"]
