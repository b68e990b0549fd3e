"""Run the server on a free loopback port, in a background thread of this process or as a
separate ``trustseek serve`` process, and a throwaway PostgreSQL cluster to run it on (used by
the tests, the benchmark and notebooks)."""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

from ..errors import TrustseekError


class ServerStartError(TrustseekError, RuntimeError):
    """A server or a PostgreSQL cluster could not be started (a RuntimeError too, as it is a
    failure of the environment rather than of an input)."""


#: how long a test waits for a server process to answer: it answers in ~1.5 s on a quiet machine,
#: but beside a test of twenty Chromium pages on two cores its start-up gets a small share of the CPU
START_TIMEOUT = 90.0


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_ready(url: str, timeout: float = START_TIMEOUT, proc: subprocess.Popen | None = None) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise ServerStartError(f"the server exited with code {proc.returncode}")
        try:
            if httpx.get(f"{url}/api/health", timeout=1.0).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.05)
    raise ServerStartError(f"the server at {url} did not start within {timeout} s")


class ThreadServer:
    """``with ThreadServer(db_url, token) as url: ...`` -- uvicorn in a daemon thread."""

    def __init__(self, db_url: str, token: str, port: int | None = None):
        import uvicorn

        from ..server.app import create_app

        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.app = create_app(db_url, token=token)
        config = uvicorn.Config(self.app, host="127.0.0.1", port=self.port, log_level="warning", access_log=False)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def __enter__(self) -> str:
        self.thread.start()
        wait_ready(self.url)
        return self.url

    def __exit__(self, *exc) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)


def serve_process(db_url: str, token: str, port: int, workers: int = 1, timeout: float = START_TIMEOUT) -> subprocess.Popen:
    """Start ``trustseek serve`` (``workers`` processes) as a child process on 127.0.0.1:port and
    wait until it answers (at most ``timeout`` seconds).  The token goes through the environment,
    not the command line.  A server that does not answer in time is stopped before the error is
    raised, so that it does not live on (holding the port and the database) after the test."""
    where = f"--host 127.0.0.1 --port {port} --workers {workers}".split()
    cmd = [sys.executable, "-c", "from trustseek.cli import main; main()", "serve", "--db", db_url, *where]
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "TRUSTSEEK_TOKEN": token}
    # stderr to a file, not a pipe (an unread pipe would block a chatty server); the child keeps its own
    # descriptor, this process closes its copy once the server answers
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, env=env)
        try:
            wait_ready(f"http://127.0.0.1:{port}", timeout=timeout, proc=proc)
        except ServerStartError as exc:
            stop_process(proc)
            err.seek(0)
            raise ServerStartError(f"{exc}\n{err.read().decode(errors='replace')[-4000:]}") from None
    return proc


def stop_process(proc: subprocess.Popen, grace: float = 10.0) -> None:
    """Stop a server process: SIGTERM (its workers stop with it), then SIGKILL after ``grace`` s."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=grace)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def postgres_binaries() -> Path | None:
    """The directory holding PostgreSQL's ``initdb``, ``pg_ctl`` and ``postgres`` (Debian's
    /usr/lib/postgresql/<version>/bin, newest first, else the one ``pg_ctl`` on PATH is in),
    or None when the server is not installed."""

    def version(d: str) -> int:
        v = Path(d).parent.name
        return int(v) if v.isdigit() else 0

    dirs = sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=version, reverse=True)
    pg_ctl = shutil.which("pg_ctl")
    if pg_ctl is not None:
        dirs.append(str(Path(os.path.realpath(pg_ctl)).parent))
    for d in dirs:
        if all((Path(d) / exe).exists() for exe in ("initdb", "pg_ctl", "postgres")):
            return Path(d)
    return None


class TemporaryPostgres:
    """A throwaway PostgreSQL cluster in a temporary directory, on 127.0.0.1:<free port>, trust
    authentication for ``postgres``, no fsync (``fsync=True``: PostgreSQL's defaults).  As root its
    programs run as the ``postgres`` user (``runuser``).  ``with TemporaryPostgres() as url:`` or
    ``start()`` / ``stop()`` (which always removes the directory).
    """

    def __init__(self, fsync: bool = False):
        self.fsync = fsync
        found = postgres_binaries()
        if found is None:
            raise ServerStartError("PostgreSQL server binaries (initdb, pg_ctl) not found: install Debian's postgresql package")
        self.bindir: Path = found
        self.prefix: list[str] = []
        self.owner: tuple[int, int] | None = None
        if os.geteuid() == 0:
            runuser = shutil.which("runuser")
            try:
                pw = pwd.getpwnam("postgres")
            except KeyError:
                pw = None
            if runuser is None or pw is None:
                raise ServerStartError("running as root, PostgreSQL needs the 'postgres' user and runuser to start a cluster")
            self.prefix, self.owner = [runuser, "-u", "postgres", "--"], (pw.pw_uid, pw.pw_gid)
        self.root: Path | None = None
        self.started = False
        self.url: str | None = None

    def _run(self, *cmd: str) -> None:
        res = subprocess.run([*self.prefix, *cmd], capture_output=True, text=True, timeout=120, cwd=self.root)
        if res.returncode != 0:
            log = None if self.root is None else self.root / "server.log"
            tail = log.read_text(errors="replace")[-2000:] if log is not None and log.exists() else ""
            raise ServerStartError(f"{Path(cmd[0]).name} failed with code {res.returncode}:\n{res.stdout}{res.stderr}{tail}")

    def start(self) -> str:
        root = self.root = Path(tempfile.mkdtemp(prefix="trustseek-pg-"))
        if self.owner is not None:
            os.chown(root, *self.owner)
        data, port = root / "data", free_port()
        initdb = ["-U", "postgres", "-A", "trust", "-E", "UTF8", "--no-sync", "--no-instructions"]
        self._run(str(self.bindir / "initdb"), "-D", str(data), *initdb)
        opts = f"-k {root} -p {port} -c listen_addresses=127.0.0.1"
        if not self.fsync:
            opts += " -c fsync=off -c full_page_writes=off"
        self.started = True  # from here on stop() runs pg_ctl stop, even if the start fails half-way
        log = str(root / "server.log")
        self._run(str(self.bindir / "pg_ctl"), "-D", str(data), "-l", log, "-o", opts, "-w", "-t", "60", "start")
        self.url = f"postgresql://postgres@127.0.0.1:{port}/postgres"
        return self.url

    def stop(self) -> None:
        try:
            if self.started and self.root is not None:
                subprocess.run(
                    [*self.prefix, str(self.bindir / "pg_ctl"), "-D", str(self.root / "data"), "-m", "immediate", "-w", "stop"],
                    capture_output=True,
                    timeout=60,
                    cwd=self.root,
                )
        finally:
            self.started = False
            if self.root is not None:
                shutil.rmtree(self.root, ignore_errors=True)
                self.root = None

    def __enter__(self) -> str:
        try:
            return self.start()
        except BaseException:
            self.stop()
            raise

    def __exit__(self, *exc) -> None:
        self.stop()
