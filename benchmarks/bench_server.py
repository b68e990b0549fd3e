"""Load benchmark of the experiment server's decision API.

A real ``trustseek serve`` process (SQLite file, loopback only) serves 100 concurrent
simulated robot sessions.  Each session runs trials: post the complexity (``decide``), wait a
think time, post the human action and outcome (``observe``).  Reported:

* decision latency p50 / p99 as seen by the client (round trip over loopback) and as spent
  in the server (``Server-Timing``), against a baseline of one session alone;
* throughput, and a check that every trial is stored exactly once (read back from the
  database file).

    python benchmarks/bench_server.py [--sessions 100] [--trials 10] [--think-ms 1000]
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import sqlite3
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from trustseek.server.local import free_port, serve_process

TOKEN = "bench-token-0123456789"


class Conn:
    """A keep-alive loopback connection (the standard library's client: little overhead of its
    own, so the latency measured is the server's plus the network stack's)."""

    def __init__(self, port: int, token: str):
        self.c = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
        self.h = {"Authorization": f"Bearer {token}", "Content-Type": "application/json"}

    def post(self, path: str, body: dict) -> tuple[int, dict, str | None]:
        self.c.request("POST", path, body=json.dumps(body), headers=self.h)
        r = self.c.getresponse()
        data = json.loads(r.read() or b"{}")
        return r.status, data, r.getheader("server-timing")


def run_session(port: int, info: dict, trials: int, think: float, seed: int, lat: list, srv: list, start: threading.Barrier) -> None:
    """One simulated robot: its own connection, trials paced by a think time."""
    rng = np.random.default_rng(seed)
    sid = info["session_id"]
    conn = Conn(port, info["token"])
    conn.c.connect()
    start.wait()
    if think:
        time.sleep(rng.uniform(0, 2) * think)  # sessions do not start in lockstep
    for n in range(1, trials + 1):
        cx = "high" if rng.random() < 0.5 else "low"
        t0 = time.perf_counter()
        status, out, timing = conn.post(f"/api/deploy/sessions/{sid}/decide", {"trial": n, "complexity": cx})
        lat.append(time.perf_counter() - t0)
        if status >= 400:
            raise RuntimeError(f"decide failed: {status} {out}")
        srv.append(float(timing.split("dur=")[1]) / 1000)
        if think:
            time.sleep(rng.uniform(0.5, 1.5) * think)
        if out["robot_action"] == "ask":
            body = {"trial": n}
        else:
            human = "intervene" if rng.random() < 0.1 else "rely"
            body = {"trial": n, "human_action": human, "outcome": None if human == "intervene" else ("success" if rng.random() < 0.9 else "failure")}
        status, out, _ = conn.post(f"/api/deploy/sessions/{sid}/observe", body)
        if status >= 400:
            raise RuntimeError(f"observe failed: {status} {out}")
        if think:
            time.sleep(rng.uniform(0.5, 1.5) * think)
    conn.c.close()


def load(port: int, sessions: int, trials: int, think: float, policy: dict) -> tuple[list, list, float, list]:
    admin = Conn(port, TOKEN)
    infos = []
    for i in range(sessions):
        status, out, _ = admin.post("/api/deploy/sessions", {"label": f"robot-{i}", "policy": policy, "seed": i})
        if status != 201:
            raise RuntimeError(f"opening a session failed: {status} {out}")
        infos.append(out)
    admin.c.close()
    lat: list[float] = []
    srv: list[float] = []
    errors: list[BaseException] = []
    start = threading.Barrier(sessions + 1)

    def target(i, info):
        try:
            run_session(port, info, trials, think, i, lat, srv, start)
        except BaseException as exc:  # reported after the run
            errors.append(exc)
            start.abort()

    threads = [threading.Thread(target=target, args=(i, info)) for i, info in enumerate(infos)]
    for t in threads:
        t.start()
    start.wait()
    t0 = time.perf_counter()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return lat, srv, time.perf_counter() - t0, [i["session_id"] for i in infos]


def pct(x: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(x) * 1000, q))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sessions", type=int, default=100)
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--think-ms", type=float, default=1000.0, help="mean pause between a decision and its observation, and between trials")
    ap.add_argument("--policy", default="trust-aware", choices=["trust-aware", "trust-agnostic", "randomized"])
    args = ap.parse_args(argv)
    # 100 client threads share one interpreter: hand the GIL over quickly so that a thread whose
    # response has arrived is not kept waiting (the default interval is 5 ms)
    sys.setswitchinterval(0.0002)
    policy = {"kind": args.policy}
    with tempfile.TemporaryDirectory() as d:
        db = Path(d) / "bench.sqlite"
        port = free_port()
        proc = serve_process(f"sqlite:///{db}", TOKEN, port)
        try:
            t = time.perf_counter()
            base_lat, base_srv, _, base_ids = load(port, 1, 50, 0.0, policy)
            print(f"  (baseline took {time.perf_counter() - t:.1f} s)", flush=True)
            lat, srv, wall, ids = load(port, args.sessions, args.trials, args.think_ms / 1000, policy)
        finally:
            proc.terminate()
            proc.wait(timeout=10)
        con = sqlite3.connect(db)
        q = f"select session_id, trial, count(*) from trials where session_id in ({','.join('?' * len(ids))}) group by session_id, trial"
        rows = con.execute(q, ids).fetchall()
        con.close()
    per_session: dict[str, list[int]] = {}
    dup = 0
    for sid, trial, k in rows:
        per_session.setdefault(sid, []).append(trial)
        dup += k > 1
    complete = all(sorted(per_session.get(s, [])) == list(range(1, args.trials + 1)) for s in ids)
    total = args.sessions * args.trials
    print(f"server decision API: {args.sessions} concurrent sessions x {args.trials} trials ({args.policy} policy, think time ~{args.think_ms:g} ms), SQLite, loopback")
    print(f"  baseline (1 session)       client p50 {pct(base_lat, 50):6.2f} ms   p99 {pct(base_lat, 99):6.2f} ms   server p50 {pct(base_srv, 50):5.2f} ms  p99 {pct(base_srv, 99):5.2f} ms")
    print(f"  {args.sessions} concurrent sessions   client p50 {pct(lat, 50):6.2f} ms   p99 {pct(lat, 99):6.2f} ms   server p50 {pct(srv, 50):5.2f} ms  p99 {pct(srv, 99):5.2f} ms")
    print(f"  p99 under load / baseline: client {pct(lat, 99) / pct(base_lat, 99):.2f}x, server {pct(srv, 99) / pct(base_srv, 99):.2f}x;  target p99 < 10 ms: "
          f"{'met' if pct(lat, 99) < 10 else 'NOT met'} (client round trip)")
    print(f"  throughput {2 * total / wall:.0f} requests/s ({total} trials in {wall:.1f} s)")
    print(f"  machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the end of the run (other processes share the cores)")
    print(f"  trials stored: {sum(len(v) for v in per_session.values())} of {total}; duplicates {dup}; every session complete and in order: {complete}")
    return 0 if complete and dup == 0 and sum(len(v) for v in per_session.values()) == total else 1


if __name__ == "__main__":
    sys.exit(main())
