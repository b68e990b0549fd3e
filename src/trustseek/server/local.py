"""Run the server on a free loopback port, in a background thread of this process or as a
separate ``trustseek serve`` process (used by the tests, the benchmark and notebooks)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_ready(url: str, timeout: float = 30.0, proc: subprocess.Popen | None = None) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"the server exited with code {proc.returncode}")
        try:
            if httpx.get(f"{url}/api/health", timeout=1.0).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.05)
    raise RuntimeError(f"the server at {url} did not start within {timeout} s")


class ThreadServer:
    """``with ThreadServer(db_url, token) as url: ...`` -- uvicorn in a daemon thread."""

    def __init__(self, db_url: str, token: str, port: int | None = None):
        import uvicorn

        from .app import create_app

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


def serve_process(db_url: str, token: str, port: int, log: Path | None = None) -> subprocess.Popen:
    """Start ``trustseek serve`` as a child process on 127.0.0.1:port and wait until it answers."""
    cmd = [sys.executable, "-c", "from trustseek.cli import main; main()", "serve", "--db", db_url,
           "--host", "127.0.0.1", "--port", str(port), "--token", token]
    out = open(log, "ab") if log is not None else subprocess.DEVNULL
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    # stderr goes to a file, not a pipe: an unread pipe would block a chatty server
    err = tempfile.TemporaryFile()
    proc = subprocess.Popen(cmd, stdout=out, stderr=err, env=env)
    try:
        wait_ready(f"http://127.0.0.1:{port}", proc=proc)
    except RuntimeError as exc:
        err.seek(0)
        raise RuntimeError(f"{exc}\n{err.read().decode(errors='replace')[-4000:]}") from None
    return proc
