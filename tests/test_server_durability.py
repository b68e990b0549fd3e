"""The decision API's durability promise: a decision or trial the server acknowledged (answered
200) is committed to the database before the answer is sent, so it survives the server process
being killed (SIGKILL) at any moment.  Robots post through a real ``trustseek serve`` process;
the process is killed while their requests are in flight; after a restart on the same database
every acknowledged trial is there, once and unchanged, and every acknowledged pending decision
is answered again as it was."""

from __future__ import annotations

import signal
import sqlite3
import threading
import time

import httpx

from trustseek.testing.servers import free_port, serve_process

TOKEN = "durability-token-0123"


def test_acknowledged_trials_survive_a_killed_server(tmp_path):
    path = tmp_path / "durable.sqlite"
    db, port = f"sqlite:///{path}", free_port()
    url = f"http://127.0.0.1:{port}"
    proc = serve_process(db, TOKEN, port)
    try:
        admin = {"Authorization": f"Bearer {TOKEN}"}
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
        proc = serve_process(db, TOKEN, port)
        with sqlite3.connect(path) as con:
            con.row_factory = sqlite3.Row
            for info in robots:
                sid = info["session_id"]
                rows = {r["trial"]: dict(r) for r in con.execute("SELECT * FROM trials WHERE session_id = ?", (sid,))}
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
