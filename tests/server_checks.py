"""Checks shared by the SQLite and PostgreSQL server tests."""

from __future__ import annotations

import io
from concurrent.futures import ThreadPoolExecutor

import httpx
import pandas as pd

from trustseek.client import Client
from trustseek.data.trials import read_trials
from trustseek.testing.servers import ThreadServer


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
