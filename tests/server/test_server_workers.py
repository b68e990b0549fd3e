"""``trustseek serve --workers 2``: two processes share the port and the database; robots whose
requests land on either process see one consistent session, and every trial is stored once."""

from __future__ import annotations

import itertools
import threading
from pathlib import Path

import httpx
import numpy as np
import pytest

from trustseek.testing.servers import free_port, serve_process

TOKEN = "workers-token-0123"


@pytest.fixture
def two_workers(tmp_path):
    db = f"sqlite:///{tmp_path / 'workers.sqlite'}"
    port = free_port()
    proc = serve_process(db, TOKEN, port, workers=2)
    children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
    if children.exists():  # Linux: the supervisor runs two worker processes
        workers = [pid for pid in children.read_text().split() if "spawn_main" in Path(f"/proc/{pid}/cmdline").read_text()]
        assert len(workers) >= 2, children.read_text()
    yield f"http://127.0.0.1:{port}"
    proc.terminate()
    proc.wait(timeout=20)


def test_robots_and_a_preview_on_two_worker_processes(two_workers):
    url = two_workers
    admin = {"Authorization": f"Bearer {TOKEN}"}
    sessions = []
    for i in range(4):
        r = httpx.post(
            f"{url}/api/deploy/sessions", json={"label": f"r{i}", "policy": {"kind": "trust-aware"}, "seed": i}, headers=admin
        )
        assert r.status_code == 201, r.text
        sessions.append(r.json())
    errors: list[str] = []

    def robot(info: dict, seed: int) -> None:
        rng = np.random.default_rng(seed)
        h = {"Authorization": f"Bearer {info['token']}"}
        base = f"{url}/api/deploy/sessions/{info['session_id']}"
        # a new connection per request: requests spread over both processes
        for n in range(1, 16):
            cx = "high" if rng.random() < 0.5 else "low"
            first = httpx.post(f"{base}/decide", json={"trial": n, "complexity": cx}, headers=h)
            again = httpx.post(f"{base}/decide", json={"trial": n, "complexity": cx}, headers=h)
            if first.status_code != 200 or again.json()["robot_action"] != first.json()["robot_action"]:
                errors.append(f"trial {n}: {first.text} / {again.text}")
                return
            if first.json()["robot_action"] == "ask":
                body = {"trial": n}
            else:
                body = {"trial": n, "human_action": "rely", "outcome": "success" if rng.random() < 0.8 else "failure"}
            obs = [httpx.post(f"{base}/observe", json=body, headers=h) for _ in range(2)]
            if [o.status_code for o in obs] != [200, 200] or [o.json()["duplicate"] for o in obs] != [False, True]:
                errors.append(f"trial {n} observe: {[o.text for o in obs]}")
                return

    threads = [threading.Thread(target=robot, args=(info, i)) for i, info in enumerate(sessions)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not errors, errors
    for info in sessions:
        state = httpx.get(
            f"{url}/api/deploy/sessions/{info['session_id']}", headers={"Authorization": f"Bearer {info['token']}"}
        ).json()
        assert [t["trial"] for t in state["trials"]] == list(range(1, 16))
        beliefs = [(t["belief"], t["belief_after"]) for t in state["trials"]]
        # the belief carries over from each trial to the next, whichever process served it
        assert all(b[1] == nxt[0] for b, nxt in itertools.pairwise(beliefs))
    check_a_preview(url, admin)


def test_workers_option_is_validated():
    from typer.testing import CliRunner

    from trustseek.cli import app

    r = CliRunner().invoke(app, ["serve", "--workers", "0"])
    assert r.exit_code == 2 and "--workers" in r.output


def check_a_preview(url: str, admin: dict[str, str]) -> None:
    """The workers share the previews' database: a preview made by one process is served by
    either, and nothing of it reaches the study's database."""
    blocks = [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "high"]}}]
    study = httpx.post(f"{url}/api/studies", json={"name": "w", "blocks": blocks}, headers=admin).json()
    link = httpx.post(f"{url}/api/studies/{study['id']}/preview", headers=admin).json()["link"]
    h = {"Authorization": f"Bearer {link.rsplit('/', 1)[-1]}"}
    # a new connection per request: requests spread over both processes
    states = [httpx.get(f"{url}/api/session", headers=h) for _ in range(6)]
    assert [r.status_code for r in states] == [200] * 6 and all(r.json()["preview"] for r in states)
    sid = states[0].json()["session_id"]
    assert httpx.post(f"{url}/api/sessions/{sid}/consent", json={"agree": True}, headers=h).status_code == 200
    for n in (1, 2):
        body = {"trial": n, "submission_id": f"p{n}", "human_action": "rely"}
        assert httpx.post(f"{url}/api/sessions/{sid}/trials", json=body, headers=h).status_code == 200
    assert httpx.get(f"{url}/api/session", headers=h).json()["ended"]
    sessions = httpx.get(f"{url}/api/studies/{study['id']}/export", params={"table": "sessions"}, headers=admin)
    assert sessions.status_code == 200 and len(sessions.text.strip().splitlines()) == 1  # the header alone
