"""The test helper that starts ``trustseek serve`` leaves nothing running when the server does not
answer in time (a loaded machine): the process is stopped before the error is raised."""

from __future__ import annotations

import time

import httpx
import pytest

from trustseek.testing.servers import ServerStartError, free_port, serve_process


def test_a_server_that_does_not_answer_in_time_is_stopped(tmp_path):
    port = free_port()
    with pytest.raises(ServerStartError, match="did not start within"):
        serve_process(f"sqlite:///{tmp_path / 'late.sqlite'}", "late-token", port, timeout=0.01)
    # the server would be up within seconds if it had been left running
    deadline = time.monotonic() + 8.0
    while time.monotonic() < deadline:
        with pytest.raises(httpx.TransportError):
            httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1.0)
        time.sleep(0.5)
