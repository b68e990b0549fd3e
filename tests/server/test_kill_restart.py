"""A real server process is killed (SIGKILL) mid-session and restarted on the same database:
the participant's and the robot's sessions resume where they left off, and no committed trial
is lost or duplicated."""

from __future__ import annotations

import io
import signal

import httpx
import pandas as pd
import pytest

from trustseek.client import Client, DeploySession
from trustseek.testing.servers import free_port, serve_process

TOKEN = "kill-restart-token"


@pytest.fixture
def server(tmp_path):
    db = f"sqlite:///{tmp_path / 'kill.sqlite'}"
    port = free_port()
    procs = []

    def start():
        p = serve_process(db, TOKEN, port)
        procs.append(p)
        return p

    yield start, f"http://127.0.0.1:{port}"
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait(timeout=10)


def test_server_killed_mid_session_resumes(server):
    start, url = server
    proc = start()
    c = Client(url, TOKEN)
    study = c.create_study(
        {
            "name": "kill",
            "blocks": [
                {
                    "policy": {"kind": "randomized", "p_ask": {"low": 0.5, "high": 0.5}},
                    "schedule": {"counts": {"low": 4, "high": 4}},
                },
            ],
        }
    )
    s = c.create_sessions(study["id"])[0]
    ph = {"Authorization": f"Bearer {s['token']}"}
    base = f"{url}/api/sessions/{s['session_id']}"
    httpx.post(f"{base}/consent", json={"agree": True}, headers=ph).raise_for_status()

    def play(n):
        cur = httpx.get(f"{base}/state", headers=ph).json()["current"]
        assert cur["trial"] == n
        human = "intervene" if cur["robot_action"] == "ask" else "rely"
        r = httpx.post(f"{base}/trials", json={"trial": n, "submission_id": f"sub-{n}", "human_action": human}, headers=ph)
        r.raise_for_status()
        return cur, human, r.json()["trial"]

    committed = [play(n) for n in (1, 2, 3)]
    before = httpx.get(f"{base}/state", headers=ph).json()  # trial 4 is now served (decided, stored)
    robot = c.open_deploy(policy={"kind": "trust-aware", "grid": 201})
    robot.decide("high")
    robot.observe("intervene")
    robot_action_2 = robot.decide("high")  # decided, not yet observed

    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    with pytest.raises(httpx.TransportError):
        httpx.get(f"{url}/api/health", timeout=1.0)
    start()

    after = httpx.get(f"{base}/state", headers=ph).json()
    assert after["trials_done"] == 3 and after["score"] == before["score"]
    assert after["current"] == before["current"]  # the same trial, complexity and action
    # the retried submission of a committed trial is recognised, not stored twice
    _, human, t3 = committed[2]
    r = httpx.post(f"{base}/trials", json={"trial": 3, "submission_id": "sub-3", "human_action": human}, headers=ph)
    assert r.status_code == 200 and r.json()["duplicate"] is True and r.json()["trial"] == t3
    for n in range(4, 9):
        play(n)
    assert httpx.get(f"{base}/state", headers=ph).json()["status"] == "done"

    frame = pd.read_csv(io.BytesIO(c.export(study["id"])))
    assert frame["trial"].tolist() == list(range(1, 9))
    assert frame[frame.trial <= 3]["outcome"].tolist() == [t["outcome"] for _, _, t in committed]
    assert sorted(frame["complexity"]) == ["high"] * 4 + ["low"] * 4

    resumed = DeploySession.resume(url, robot.session_id, robot.token)
    assert resumed.trial == 1
    assert resumed.state()["pending"]["robot_action"] == robot_action_2
    assert resumed.decide("high") == robot_action_2
    resumed.observe(None if robot_action_2 == "ask" else "rely", None if robot_action_2 == "ask" else "success")
    assert [t["trial"] for t in resumed.state()["trials"]] == [1, 2]
