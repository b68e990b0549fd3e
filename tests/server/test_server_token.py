"""`trustseek serve` and the experimenter token: read from $TRUSTSEEK_TOKEN or --token-file,
never printed; a generated one goes to a file only its owner can read."""

from __future__ import annotations

import stat

import pytest
from typer.testing import CliRunner

from trustseek.cli import app
from trustseek.errors import TrustseekError


@pytest.fixture
def started(monkeypatch, tmp_path):
    """Run ``serve`` without listening: record the token the app was made with."""
    import uvicorn

    import trustseek.server

    made: dict[str, str] = {}

    def create_app(db, token=None, public_url=None):
        made["token"] = token
        return object()

    monkeypatch.setattr(trustseek.server, "create_app", create_app)
    monkeypatch.setattr(uvicorn, "run", lambda *a, **k: None)
    monkeypatch.delenv("TRUSTSEEK_TOKEN", raising=False)
    monkeypatch.chdir(tmp_path)
    return made


def serve(*args: str, env: dict[str, str] | None = None):
    return CliRunner().invoke(app, ["serve", "--db", "sqlite:///x.sqlite", *args], env=env)


def test_token_from_the_environment_is_not_printed(started):
    secret = "env-secret-token-123"
    res = serve(env={"TRUSTSEEK_TOKEN": secret})
    assert res.exit_code == 0, res.output
    assert started["token"] == secret
    assert secret not in res.output
    assert "$TRUSTSEEK_TOKEN" in res.output


def test_token_from_the_command_line_is_not_printed(started):
    res = serve("--token", "cli-secret-token-123")
    assert res.exit_code == 0, res.output
    assert started["token"] == "cli-secret-token-123" and "cli-secret-token-123" not in res.output


def test_token_file(started, tmp_path):
    f = tmp_path / "tok"
    f.write_text("file-secret-token-1\nignored\n")
    res = serve("--token-file", str(f), env={"TRUSTSEEK_TOKEN": "env-secret-token-123"})
    assert res.exit_code == 0, res.output
    assert started["token"] == "file-secret-token-1"
    assert "file-secret-token-1" not in res.output and str(f) in res.output


@pytest.mark.parametrize("content", ["", "short\n"])
def test_token_file_refused(started, tmp_path, content):
    f = tmp_path / "tok"
    f.write_text(content)
    res = serve("--token-file", str(f))
    assert isinstance(res.exception, TrustseekError) and "at least 8 characters" in str(res.exception)
    assert "token" not in started
    res = serve("--token-file", str(tmp_path / "missing"))
    assert isinstance(res.exception, TrustseekError) and "cannot read" in str(res.exception)


def test_generated_token_goes_to_an_owner_only_file(started, tmp_path):
    res = serve()
    assert res.exit_code == 0, res.output
    token = started["token"]
    path = tmp_path / "trustseek-token"
    assert path.read_text().strip() == token and len(token) >= 20
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert token not in res.output and str(path) in res.output
    # and it can be given back
    res = serve("--token-file", str(path))
    assert res.exit_code == 0 and started["token"] == token
