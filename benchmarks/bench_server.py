"""Load benchmark of the experiment server's decision API.

A real ``trustseek serve`` process (a SQLite file by default, or ``--db`` a PostgreSQL URL;
loopback only) serves 100 concurrent simulated robot sessions.  Each session runs trials:
post the complexity (``decide``), wait a think time, post the human action and outcome
(``observe``), wait again.  Reported, for a single session alone (the baselines, measured in
the same run against the same server) and for the concurrent sessions:

* decision latency p50 / p99 at the client (the round trip over loopback: request written to
  response body read) and in the server (``Server-Timing: app``: from the request reaching the
  application to its response headers);
* two baselines: one session posting back to back (everything warm), and one session paced
  by a short think time (a request that arrives after an idle pause is served from colder
  caches, as each request of the concurrent run is, so this is the fair comparison);
* throughput, the machine's load average, and a check that every trial is stored exactly
  once (read back from the database).

The load model: each session is one robot with its own keep-alive connection; it starts after
a pause drawn uniformly in [0, 2] think times, then per trial posts ``decide``, pauses
U(0.5, 1.5) think times, posts ``observe``, pauses U(0.5, 1.5) think times: with the default
1000 ms, one request per second per session, so N sessions offer about N requests/s.  The
pause is counted from the answer, so a slow server is offered less (the throughput printed is
what was served).  The load generator is one asyncio event loop (uvloop) in this process, the
server another process; it uses a minimal HTTP/1.1 exchange, so that its own overhead stays
small against what it measures, and its CPU time per request is printed.

``--profile`` runs the server under cProfile (its main thread's CPU time) and prints where the
server's CPU time per request goes: event loop and sockets, HTTP parsing and the ASGI server,
JSON, the policy, the database driver, the lean path's own code, and the full application (which opens the
sessions).  Profiling slows the server about twice: its latencies are not the figures to quote.

    python benchmarks/bench_server.py [--sessions 100] [--trials 10] [--think-ms 1000] [--db URL | --postgres] [--profile]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np
from sqlalchemy import create_engine, text

from trustseek.server.db import driver_url
from trustseek.testing.servers import TemporaryPostgres, free_port, serve_process, wait_ready

TOKEN = "bench-token-0123456789"


class Conn:
    """One keep-alive HTTP/1.1 connection to the server over loopback."""

    def __init__(self, port: int, token: str):
        self.port = port
        self.head = f"Host: 127.0.0.1:{port}\r\nAuthorization: Bearer {token}\r\nContent-Type: application/json\r\n".encode()

    async def open(self) -> Conn:
        self.reader, self.writer = await asyncio.open_connection("127.0.0.1", self.port)
        return self

    async def post(self, path: str, body: dict) -> tuple[int, dict, float | None, float]:
        """(status, JSON body, server time in s from Server-Timing, client round trip in s)."""
        data = json.dumps(body).encode()
        t0 = time.perf_counter()
        self.writer.write(
            b"POST " + path.encode() + b" HTTP/1.1\r\n" + self.head + b"Content-Length: %d\r\n\r\n" % len(data) + data
        )
        head = await self.reader.readuntil(b"\r\n\r\n")
        fields = dict(line.split(b":", 1) for line in head.split(b"\r\n")[1:] if b":" in line)
        fields = {k.strip().lower(): v.strip() for k, v in fields.items()}
        payload = await self.reader.readexactly(int(fields[b"content-length"]))
        rtt = time.perf_counter() - t0
        timing = fields.get(b"server-timing")
        srv = float(timing.split(b"dur=")[1].split(b",")[0]) / 1000 if timing else None
        return int(head[9:12]), json.loads(payload or b"{}"), srv, rtt

    def close(self) -> None:
        self.writer.close()


async def run_session(port: int, info: dict, trials: int, think: float, seed: int, lat: list, srv: list) -> None:
    """One simulated robot: its own connection, trials paced by a think time."""
    rng = np.random.default_rng(seed)
    sid = info["session_id"]
    conn = await Conn(port, info["token"]).open()
    if think:
        await asyncio.sleep(rng.uniform(0, 2) * think)  # sessions do not start in lockstep
    for n in range(1, trials + 1):
        cx = "high" if rng.random() < 0.5 else "low"
        status, out, s, rtt = await conn.post(f"/api/deploy/sessions/{sid}/decide", {"trial": n, "complexity": cx})
        if status >= 400:
            raise RuntimeError(f"decide failed: {status} {out}")
        lat.append(rtt)
        srv.append(s)
        if think:
            await asyncio.sleep(rng.uniform(0.5, 1.5) * think)
        if out["robot_action"] == "ask":
            body = {"trial": n}
        else:
            human = "intervene" if rng.random() < 0.1 else "rely"
            body = {
                "trial": n,
                "human_action": human,
                "outcome": None if human == "intervene" else ("success" if rng.random() < 0.9 else "failure"),
            }
        status, out, _, _ = await conn.post(f"/api/deploy/sessions/{sid}/observe", body)
        if status >= 400:
            raise RuntimeError(f"observe failed: {status} {out}")
        if think:
            await asyncio.sleep(rng.uniform(0.5, 1.5) * think)
    conn.close()


async def load(
    port: int,
    sessions: int,
    trials: int,
    think: float,
    policy: dict,
    first_seed: int = 0,
    pid: int | None = None,
    db_pid: int | None = None,
) -> tuple[list, list, float, list, float, float, float]:
    """Open the sessions, then run them concurrently: (client latencies, server latencies, wall
    time, session ids, server CPU seconds (process ``pid`` and its children), this process's
    CPU seconds and the database's (PostgreSQL: the postmaster ``db_pid`` and its backends)
    while they ran)."""
    admin = await Conn(port, TOKEN).open()
    infos = []
    for i in range(sessions):
        status, out, _, _ = await admin.post(
            "/api/deploy/sessions", {"label": f"robot-{first_seed + i}", "policy": policy, "seed": first_seed + i}
        )
        if status != 201:
            raise RuntimeError(f"opening a session failed: {status} {out}")
        infos.append(out)
    admin.close()
    lat: list[float] = []
    srv: list[float] = []
    cpu0 = server_cpu(pid) if pid is not None else 0.0
    db0 = server_cpu(db_pid) if db_pid is not None else 0.0
    own0 = time.process_time()
    t0 = time.perf_counter()
    await asyncio.gather(*(run_session(port, info, trials, think, first_seed + i, lat, srv) for i, info in enumerate(infos)))
    wall = time.perf_counter() - t0
    cpu = server_cpu(pid) - cpu0 if pid is not None else float("nan")
    own = time.process_time() - own0
    db = server_cpu(db_pid) - db0 if db_pid is not None else float("nan")
    return lat, srv, wall, [i["session_id"] for i in infos], cpu, own, db


def pct(x: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(x) * 1000, q))


def stored_trials(url: str, ids: list[str]) -> list[tuple[str, int, int]]:
    engine = create_engine(driver_url(url))
    names = ", ".join(f":s{i}" for i in range(len(ids)))
    q = text(f"select session_id, trial, count(*) from trials where session_id in ({names}) group by session_id, trial")
    with engine.connect() as c:
        rows = [tuple(r) for r in c.execute(q, {f"s{i}": s for i, s in enumerate(ids)})]
    engine.dispose()
    return rows


def server_cpu(pid: int) -> float:
    """CPU seconds (user + system) used so far by a process and its children (the workers), from
    /proc (Linux)."""
    stats = {}
    for f in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError):
            fields = f.read_text().rsplit(")", 1)[1].split()
            stats[int(f.parent.name)] = (int(fields[1]), (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK"))
    tree, grew = {pid}, True
    while grew:
        more = {p for p, (ppid, _) in stats.items() if ppid in tree} - tree
        tree |= more
        grew = bool(more)
    return sum(stats[p][1] for p in tree if p in stats)


def source_of(rev: str, into: Path) -> Path:
    """The ``src`` folder of git revision ``rev`` of this repository, extracted under ``into``."""
    repo = Path(__file__).resolve().parent.parent
    data = subprocess.run(["git", "-C", str(repo), "archive", rev, "src"], check=True, capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        tar.extractall(into, filter="data")
    return into / "src"


FLOOR = "floor"

CATEGORIES = [
    ("event loop, sockets (uvloop and the kernel)", ("asyncio", "uvloop", "selectors")),
    ("HTTP parsing, ASGI server (uvicorn, httptools)", ("uvicorn", "httptools")),
    ("JSON (json)", ("/json/",)),
    ("database statements and commits (store, sqlite3, psycopg)", ("sqlite3", "deploy/store.py", "psycopg")),
    ("policy decision and belief update", ("/policies/", "/pomdp/", "numpy", "/model/")),
    (
        "decision API: auth, checks, trial record",
        ("server/deploy/", "server/cache.py", "sessions.py", "auth.py", "server/app.py", "orm.py"),
    ),
    ("full application (opening the sessions)", ("fastapi", "starlette", "sqlalchemy", "pydantic", "routes.py", "middleware.py")),
]


def serve_profiled(db: str, port: int, out: str) -> None:
    """``trustseek serve``'s application and server settings, under cProfile (main thread CPU
    time); the statistics go to ``out`` when the server stops (SIGINT)."""
    import cProfile

    import uvicorn

    from trustseek.server.app import create_app, settle_memory

    app = create_app(db, token=TOKEN)
    settle_memory()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning", access_log=False))
    prof = cProfile.Profile(time.thread_time)
    prof.enable()
    with contextlib.suppress(KeyboardInterrupt):
        server.run()
    prof.disable()
    prof.dump_stats(out)


def profiled_process(db: str, port: int, out: Path) -> subprocess.Popen:
    cmd = [sys.executable, __file__, "--serve-profiled", db, str(port), str(out)]
    proc = subprocess.Popen(cmd, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    wait_ready(f"http://127.0.0.1:{port}", proc=proc)
    return proc


def cpu_split(stats_file: Path, requests: int) -> list[tuple[str, float]]:
    """(category, profiled CPU ms per request) from the server's cProfile statistics."""
    import pstats

    def category(file: str, name: str) -> str:
        where = f"{file} {name}"
        return next((c for c, keys in CATEGORIES if any(k in where for k in keys)), "other")

    by: dict[str, float] = {}
    for (file, _, name), (_, _, own, _, callers) in pstats.Stats(str(stats_file)).stats.items():  # type: ignore[attr-defined]
        label = category(file, name)
        if file == "~" and label == "other" and callers:  # a built-in: its callers' part, per call edge
            for (cfile, _, cname), edge in callers.items():
                by[category(cfile, cname)] = by.get(category(cfile, cname), 0.0) + edge[2]
            continue
        by[label] = by.get(label, 0.0) + own
    return [(c, by.get(c, 0.0) / requests * 1000) for c, _ in [*CATEGORIES, ("other", ())]]


async def floor_app(scope, receive, send) -> None:
    """The floor: an ASGI application that answers every request at once with a fixed body
    (a session for the opening request, an autonomous decision for the others), served by
    uvicorn as ``trustseek serve`` is.  What it costs is the HTTP server's, the event loop's
    and the kernel's share of a request, which no change to the application can remove."""
    if scope["type"] != "http":
        return
    t0 = time.perf_counter()
    while (await receive()).get("more_body"):
        pass
    opening = scope["path"] == "/api/deploy/sessions"
    body = b'{"session_id":"floor","token":"floor","robot_action":"autonomous"}'
    timing = b"app;dur=%.3f" % ((time.perf_counter() - t0) * 1000)
    head = [(b"content-length", b"%d" % len(body)), (b"content-type", b"application/json"), (b"server-timing", timing)]
    await send({"type": "http.response.start", "status": 201 if opening else 200, "headers": head})
    await send({"type": "http.response.body", "body": body})


def floor_process(port: int) -> subprocess.Popen:
    here = str(Path(__file__).resolve().parent)
    cmd = [sys.executable, "-m", "uvicorn", "--app-dir", here, "bench_server:floor_app", "--host", "127.0.0.1"]
    proc = subprocess.Popen([*cmd, "--port", str(port), "--log-level", "warning", "--no-access-log"])
    wait_ready(f"http://127.0.0.1:{port}", proc=proc)
    return proc


def measure(
    url: str,
    src: Path | None,
    args,
    levels: list[int],
    policy: dict,
    seed0: int,
    profile: Path | None = None,
    db_pid: int | None = None,
) -> dict:
    """Start a server (from ``src`` when given, else this checkout; under the profiler when
    ``profile`` names the statistics file) and run the baselines and each level of concurrent
    sessions against it (``db_pid``: the PostgreSQL cluster's postmaster, whose CPU is counted)."""
    port = free_port()
    env = os.environ.get("PYTHONPATH")
    if src is not None:
        os.environ["PYTHONPATH"] = str(src)
    try:
        if url == FLOOR:
            proc = floor_process(port)
        elif profile is not None:
            proc = profiled_process(url, port, profile)
        else:
            proc = serve_process(url, TOKEN, port, workers=args.workers)
    finally:
        if env is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = env
    out: dict = {"levels": {}}
    try:
        asyncio.run(load(port, 1, 5, 0.0, policy, first_seed=seed0))  # warm-up: imports, caches, connections
        out["back"] = asyncio.run(load(port, 1, args.baseline_trials, 0.0, policy, first_seed=seed0 + 1))[:2]
        out["paced"] = asyncio.run(
            load(port, 1, args.baseline_trials, args.baseline_think_ms / 1000, policy, first_seed=seed0 + 2)
        )[:2]
        for k, n in enumerate(levels):
            load_before = os.getloadavg()[0]
            lat, srv, wall, ids, cpu, own, db = asyncio.run(
                load(
                    port,
                    n,
                    args.trials,
                    args.think_ms / 1000,
                    policy,
                    first_seed=seed0 + 100 + k * 100_000,
                    pid=proc.pid,
                    db_pid=db_pid,
                )
            )
            out["levels"][n] = {
                "lat": lat,
                "srv": srv,
                "wall": wall,
                "ids": ids,
                "cpu": cpu,
                "client_cpu": own,
                "db_cpu": db,
                "load": (load_before, os.getloadavg()[0]),
            }
    finally:
        proc.send_signal(signal.SIGINT) if profile is not None else proc.terminate()
        proc.wait(timeout=60)
    for r in out["levels"].values():
        r["rows"] = None if url == FLOOR else stored_trials(url, r["ids"])
    return out


def check(rows: list, ids: list[str], trials: int) -> tuple[int, int, bool]:
    """(trials stored, duplicated (session, trial) pairs, every session complete and in order)."""
    per_session: dict[str, list[int]] = {}
    dup = 0
    for sid, trial, k in rows:
        per_session.setdefault(sid, []).append(trial)
        dup += k > 1
    complete = all(sorted(per_session.get(s, [])) == list(range(1, trials + 1)) for s in ids)
    return sum(len(v) for v in per_session.values()), dup, complete


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sessions", default="100", help="concurrent sessions; several levels separated by commas (100,300,1000)")
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument(
        "--think-ms", type=float, default=1000.0, help="mean pause between a decision and its observation, and between trials"
    )
    ap.add_argument("--baseline-trials", type=int, default=100, help="trials of each single-session baseline")
    ap.add_argument("--baseline-think-ms", type=float, default=50.0, help="think time of the paced single-session baseline")
    ap.add_argument("--policy", default="trust-aware", choices=["trust-aware", "trust-agnostic", "randomized"])
    ap.add_argument("--db", default=None, help="database URL (default: a SQLite file in a temporary directory)")
    ap.add_argument("--workers", type=int, default=1, help="server processes (trustseek serve --workers)")
    ap.add_argument("--postgres", action="store_true", help="run on a throwaway PostgreSQL cluster (Debian's postgresql package)")
    ap.add_argument(
        "--pg-fsync",
        action="store_true",
        help="the throwaway cluster with fsync on, as a real database runs (by default off: its commits do not wait for the disk)",
    )
    ap.add_argument(
        "--baseline-rev",
        default=None,
        help="also measure the server of this git revision (e.g. HEAD~3), first, in the same run and on a fresh database of its own",
    )
    ap.add_argument(
        "--floor",
        action="store_true",
        help="also measure the floor: a trivial application under uvicorn (what HTTP, the event loop and the kernel cost)",
    )
    ap.add_argument(
        "--profile", action="store_true", help="also run this checkout's server under cProfile: its CPU time per request, by part"
    )
    ap.add_argument("--serve-profiled", nargs=3, metavar=("DB", "PORT", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.serve_profiled:
        db, port, out = args.serve_profiled
        serve_profiled(db, int(port), out)
        return 0
    levels = [int(x) for x in args.sessions.split(",")]
    try:
        import uvloop

        uvloop.install()
    except ImportError:
        pass
    policy = {"kind": args.policy}
    start_load = os.getloadavg()
    results = []
    backend = "none"
    with tempfile.TemporaryDirectory() as d, contextlib.ExitStack() as stack:
        variants: list[tuple[str, Path | None]] = [("this checkout", None)]
        if args.baseline_rev:
            variants.insert(0, (f"revision {args.baseline_rev}", source_of(args.baseline_rev, Path(d) / "baseline")))
        if args.floor:
            variants.append((FLOOR, None))
        if args.profile:
            variants.append(("this checkout, profiled", None))
        for k, (name, src) in enumerate(variants):
            db_pid = None
            if name == FLOOR:
                url = FLOOR
            elif args.postgres:
                cluster = TemporaryPostgres(fsync=args.pg_fsync)
                url = stack.enter_context(cluster)
                assert cluster.root is not None
                db_pid = int((cluster.root / "data" / "postmaster.pid").read_text().split()[0])
            else:
                url = args.db or f"sqlite:///{Path(d) / f'bench-{k}.sqlite'}"
            prof = Path(d) / "server.prof" if name.endswith("profiled") else None
            res = measure(url, src, args, levels, policy, seed0=10**6 * (k + 1), profile=prof, db_pid=db_pid)
            if prof is not None:
                served = sum(len(r["lat"]) * 2 for r in res["levels"].values()) + 2 * (5 + 2 * args.baseline_trials)
                res["split"] = cpu_split(prof, served)
            results.append((name, res))
            if url != FLOOR:
                backend = url.split(":", 1)[0].split("+")[0]
    print(
        f"server decision API: concurrent sessions x {args.trials} trials ({args.policy} policy, think time ~{args.think_ms:g} ms), "
        f"{backend}, {args.workers} server process(es), loopback; the load generator is this process"
    )
    print(
        f"  load model: per session (robot) one keep-alive connection, a start within [0, {2 * args.think_ms:g}] ms, then per trial "
        f"decide, pause U(0.5, 1.5) x {args.think_ms:g} ms, observe, pause U(0.5, 1.5) x {args.think_ms:g} ms: "
        f"~{1000 / args.think_ms:.2g} request/s per session offered"
    )
    print(f"  machine load (1, 5, 15 min) at the start: {' '.join(f'{x:.2f}' for x in start_load)}")
    ok = True
    for name, res in results:
        print(f" server of {name}:" if name != FLOOR else " floor (an application that does nothing, under uvicorn):")
        rows_out = [
            ("1 session, back to back", *res["back"]),
            (f"1 session, paced {args.baseline_think_ms:g} ms", *res["paced"]),
        ]
        for label, c, v in rows_out:
            print(
                f"  {label:<30} client p50 {pct(c, 50):7.2f} ms  p99 {pct(c, 99):8.2f} ms   server p50 {pct(v, 50):5.2f} ms  p99 {pct(v, 99):6.2f} ms"
            )
        for n, r in res["levels"].items():
            lat, srv, total = r["lat"], r["srv"], n * args.trials
            if r["rows"] is None:
                stored, dup, complete = total, 0, True
            else:
                stored, dup, complete = check(r["rows"], r["ids"], args.trials)
                ok = ok and complete and dup == 0 and stored == total
            print(
                f"  {f'{n} concurrent sessions':<30} client p50 {pct(lat, 50):7.2f} ms  p99 {pct(lat, 99):8.2f} ms   "
                f"server p50 {pct(srv, 50):5.2f} ms  p99 {pct(srv, 99):6.2f} ms"
            )
            print(
                f"  {'':<30} {2 * total / r['wall']:.0f} requests/s, CPU per request: server {r['cpu'] / (2 * total) * 1000:.2f} ms, load generator {r['client_cpu'] / (2 * total) * 1000:.2f} ms"
                + ("" if r["db_cpu"] != r["db_cpu"] else f", PostgreSQL {r['db_cpu'] / (2 * total) * 1000:.2f} ms")
                + "; "
                f"p99 < 10 ms {'met' if pct(lat, 99) < 10 else 'NOT met'}; load average {r['load'][0]:.2f} before, {r['load'][1]:.2f} after"
                + (
                    ""
                    if r["rows"] is None
                    else f"; trials stored {stored} of {total}, duplicates {dup}, complete and in order: {complete}"
                )
            )
        if "split" in res:
            print("  server CPU per decide/observe under the profiler (main thread; profiling inflates Python code ~2x):")
            for label, ms in res["split"]:
                print(f"    {label:<50} {ms:6.3f} ms")
            print(f"    {'total':<50} {sum(ms for _, ms in res['split']):6.3f} ms")
    print(
        f"  machine: {os.cpu_count()} cores shared with other processes; load (1, 5, 15 min) at the end: "
        + " ".join(f"{x:.2f}" for x in os.getloadavg())
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
