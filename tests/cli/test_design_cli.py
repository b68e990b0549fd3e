"""The design command: JSON output, the HTML page and its figures, refused options."""

from __future__ import annotations

import contextlib
import json
import socket
import threading

import pytest
from typer.testing import CliRunner

from cli_runner import run_cli
from trustseek.cli import app
from trustseek.cli import design as design_cli

SMALL = ["-r", "2", "--participants-1", "6", "--trials-1", "40", "--participants-2", "4,8", "--trials-2", "20", "--restarts", "1"]


def test_design_json_and_report(tmp_path):
    out = tmp_path / "study"
    res = CliRunner().invoke(
        app, ["design", *SMALL, "--json", "-q", "-o", str(out), "--search-ask-low", "0.1,0.3", "--search-ask-high", "0.4"]
    )
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    point = doc["design"]["points"][0]
    assert point["experiment1"] == {"participants": 6, "trials": 40, "counts": [23, 17], "ask_low": 0.1, "ask_high": 0.4}
    assert [c["participants"] for c in point["experiment2"][0]["curve"]] == [4, 8]
    assert {(r["ask_low"], r["ask_high"]) for r in doc["ask_search"]["rows"]} == {(0.1, 0.4), (0.3, 0.4)}
    html = (out / "design.html").read_text(encoding="utf-8")
    assert html.count("data:image/png;base64,") == 3
    assert "Experiment 2: power" in html and "ask probabilities" in html
    assert json.loads((out / "design.json").read_text())["design"] == doc["design"]


def test_design_tables(tmp_path):
    res = CliRunner().invoke(app, ["design", *SMALL, "-q"])
    assert res.exit_code == 0, res.output
    assert "participants for power 0.8" in res.stdout and "V* = " in res.stdout


def test_design_refuses_bad_grids():
    from trustseek.errors import TrustseekError

    res = CliRunner().invoke(app, ["design", "--participants-2", "1,x"])
    assert isinstance(res.exception, TrustseekError)
    assert "--participants-2" in " ".join(res.exception.lines())
    res = CliRunner().invoke(app, ["design", "--alpha", "2", "--replicates", "1"])
    assert isinstance(res.exception, TrustseekError)
    text = " ".join(res.exception.lines())
    assert "--alpha" in text and "--replicates" in text


@contextlib.contextmanager
def _listener(reply: bytes | None):
    """A TCP port where something that is not a Dask scheduler listens: it sends ``reply`` to each
    connection (None: nothing, the connection held open)."""
    server = socket.create_server(("127.0.0.1", 0))
    held: list[socket.socket] = []

    def serve() -> None:
        with contextlib.suppress(OSError):
            while True:
                conn, _ = server.accept()
                held.append(conn)
                if reply is not None:
                    conn.sendall(reply)

    threading.Thread(target=serve, daemon=True).start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        server.close()
        for conn in held:
            conn.close()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize(
    ("where", "expected"),
    [
        ("refused", "cannot connect ("),  # waited dask's 30 s timeout
        ("another protocol", "what answers there is not a Dask scheduler ("),  # a traceback
        ("silent", "something listens there but no Dask scheduler answered in 1 s"),  # waited until the server hung up
    ],
)
def test_a_scheduler_address_where_no_scheduler_answers_is_refused_in_seconds(monkeypatch, where, expected):
    monkeypatch.setattr(design_cli, "ANSWER_SECONDS", 1)
    reply = {"another protocol": b"\xff" * 64, "silent": None}.get(where)
    with contextlib.ExitStack() as stack:
        address = f"tcp://127.0.0.1:{_free_port()}" if where == "refused" else stack.enter_context(_listener(reply))
        code, output = run_cli(["design", "--scheduler", address])
    text = " ".join(output.split())
    assert code == 2 and "Traceback" not in output and f"--scheduler {address}: {expected}" in text, output


@pytest.mark.parametrize(
    ("address", "expected"),
    [("nonsense://", "unknown address scheme 'nonsense'"), ("tcp://[::1", "invalid address"), ("tcp://host", "missing port")],
)
def test_a_scheduler_address_dask_cannot_parse_is_refused_with_its_reason(address, expected):
    code, output = run_cli(["design", "--scheduler", address])
    text = " ".join(output.split())
    assert code == 2 and f"--scheduler {address!r}: {expected}" in text and "such as tcp://host:8786" in text, output
