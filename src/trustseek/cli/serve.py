"""Experiment server commands: serve, export, study (the lifecycle)."""

from __future__ import annotations

import ipaddress
import logging
import os
import secrets
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import typer

from ..errors import TrustseekError
from ._app import atomic_output, check_output, check_outputs, command, console, print_json, write_atomic
from ._options import json_option

StudyArg = typer.Argument(..., help="Study id.")
StudyDbOpt = typer.Option("sqlite:///trustseek.sqlite", "--db", help="Database URL.")
SummaryJsonOpt = json_option("Print a JSON summary.")


def _check_db(db: str) -> str:
    if "://" not in db:
        raise TrustseekError(
            [f"--db must be a database URL such as sqlite:///study.sqlite or postgresql://user@host/db, got {db!r}"]
        )
    return db


def _check_existing_sqlite(db: str) -> Path | None:
    """A database URL to read from; a SQLite file that does not exist would be created empty:
    refused.  The SQLite file it names (None for another database)."""
    from sqlalchemy.engine import make_url

    _check_db(db)
    try:
        url = make_url(db)
    except Exception:
        raise TrustseekError([f"--db: cannot parse the database URL {db!r}"]) from None
    if url.get_backend_name() != "sqlite":
        return None
    name = url.database or ""
    if not name:
        raise TrustseekError([f"--db {db}: names no SQLite file; expected e.g. sqlite:///study.sqlite"])
    if name == ":memory:" or name.startswith("file:"):
        return None
    path = Path(name)
    if not path.is_file():
        raise TrustseekError(
            [f"--db {db}: the SQLite file {path} does not exist (run 'trustseek serve --db {db}' to create a study database)"]
        )
    return path


@command("serve")
def serve(
    db: str = typer.Option(
        "sqlite:///trustseek.sqlite", "--db", help="Database URL: a SQLite file (default) or postgresql://..."
    ),
    host: str = typer.Option("127.0.0.1", "--host", help="Address to listen on."),
    port: int = typer.Option(8000, "--port", min=0, max=65535, help="Port to listen on."),
    token: str | None = typer.Option(
        None,
        "--token",
        envvar="TRUSTSEEK_TOKEN",
        help="Experimenter token (default: $TRUSTSEEK_TOKEN). Prefer the variable or --token-file: "
        "a command line is visible to other users (ps).",
    ),
    token_file: Path | None = typer.Option(
        None,
        "--token-file",
        help="Read the experimenter token from this file (its first line). Without a token, a random one is "
        "written to ./trustseek-token (owner-only permissions) and its path printed.",
    ),
    public_url: str | None = typer.Option(
        None, "--public-url", help="Base URL used in participant links (default: the request's)."
    ),
    workers: int = typer.Option(
        1,
        "--workers",
        min=1,
        max=64,
        help="Server processes sharing the port (e.g. the number of cores, for many robots at once); "
        "they share the database, so sessions stay consistent.",
    ),
    log_level: str = typer.Option(
        "warning",
        "--log-level",
        help="uvicorn log level; trustseek's own log (studies, sessions, refused requests) goes to stderr at info, "
        "or debug with --log-level debug.",
    ),
) -> None:
    """The schema is migrated at start-up.  The OpenAPI description is at /docs and /openapi.json."""
    import uvicorn

    from ..server import create_app
    from ..server.app import settle_memory

    _check_db(db)
    token, token_source = _experimenter_token(token, token_file)
    with log_to_stderr(log_level):  # the server's log, while it runs
        application = create_app(db, token=token, public_url=public_url)  # migrates the schema, once
        try:
            loopback = ipaddress.ip_address(host).is_loopback
        except ValueError:
            loopback = host == "localhost"
        shown = "localhost" if host in ("0.0.0.0", "::") else host
        console.print(f"[bold]trustseek server[/] on http://{shown}:{port}  (database {db})")
        console.print(f"  dashboard:   http://{shown}:{port}/dashboard")
        console.print(f"  API docs:    http://{shown}:{port}/docs")
        # the token itself is never printed: only where it comes from
        console.print(f"  experimenter token: {token_source}", soft_wrap=True)
        if not loopback:
            console.print("[yellow]  listening beyond loopback: put the server behind HTTPS[/]")
        settle_memory()  # garbage-collector pauses out of request latencies
        where: dict[str, Any] = {"host": host, "port": port, "log_level": log_level, "access_log": False}
        if workers == 1:
            uvicorn.run(application, **where)
            return
        # each worker builds its own app from the environment (the token never appears in argv)
        from ..server.app import ENV_DB, ENV_PREVIEW_DB, ENV_PUBLIC_URL, ENV_TOKEN

        console.print(f"  workers:     {workers} processes")
        with tempfile.TemporaryDirectory(prefix="trustseek-previews-") as previews:  # the workers' previews, shared
            preview_db = f"sqlite:///{Path(previews) / 'previews.sqlite'}"
            os.environ.update({ENV_DB: db, ENV_TOKEN: token, ENV_PUBLIC_URL: public_url or "", ENV_PREVIEW_DB: preview_db})
            uvicorn.run("trustseek.server.app:from_environment", factory=True, workers=workers, **where)


GENERATED_TOKEN_FILE = Path("trustseek-token")


def _experimenter_token(token: str | None, token_file: Path | None) -> tuple[str, str]:
    """The experimenter token and a description of where it comes from (what start-up prints).

    ``--token-file`` wins over ``--token`` / ``$TRUSTSEEK_TOKEN``; without either, a random token
    is written to :data:`GENERATED_TOKEN_FILE` with owner-only permissions (0600)."""
    if token_file is not None:
        try:
            lines = token_file.read_text(encoding="utf-8").splitlines()
        except OSError as exc:
            raise TrustseekError([f"--token-file {token_file}: cannot read it ({exc.strerror or exc})"]) from None
        except UnicodeDecodeError:
            raise TrustseekError([f"--token-file {token_file}: not a UTF-8 text file"]) from None
        token = lines[0].strip() if lines else ""
        if len(token) < 8:
            raise TrustseekError([f"--token-file {token_file}: the token on its first line must be at least 8 characters"])
        return token, f"read from {token_file}"
    if token is not None:
        if len(token) < 8:
            raise TrustseekError(["--token must be at least 8 characters"])
        from_env = os.environ.get("TRUSTSEEK_TOKEN") == token
        return token, "from $TRUSTSEEK_TOKEN" if from_env else "from --token"
    token = secrets.token_urlsafe(24)
    path = GENERATED_TOKEN_FILE.resolve()
    try:
        with atomic_output(path) as tmp:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(token + "\n")
            os.chmod(tmp, 0o600)
    except OSError as exc:
        raise TrustseekError(
            [f"cannot write the generated token to {path} ({exc.strerror or exc}): pass --token-file or set $TRUSTSEEK_TOKEN"]
        ) from None
    return token, f"generated, in {path} (readable by you only; reuse it with --token-file {path})"


class CurrentStderr(logging.StreamHandler):
    """A log handler on the process's stderr as it is when a record is written, not as it was
    when the handler was made (a command run in-process, as tests run it, would otherwise leave
    the handler on a stream closed since)."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


@contextmanager
def log_to_stderr(level: str) -> Iterator[None]:
    """Within: the ``trustseek`` loggers on stderr, INFO and above or ``level`` if it is lower
    (a command run in-process, as the tests run it, leaves no handler behind)."""
    logger = logging.getLogger("trustseek")
    handler = CurrentStderr()
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    before = logger.level
    logger.addHandler(handler)
    logger.setLevel(min(logging.INFO, logging.getLevelNamesMapping().get(level.upper(), logging.INFO)))
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(before)


@command("export")
def export_cmd(
    study: str = StudyArg,
    db: str = StudyDbOpt,
    out: Path | None = typer.Option(
        None, "--out", "-o", help="Trial log to write (.csv or .parquet): the canonical format `trustseek fit` reads."
    ),
    events: Path | None = typer.Option(None, "--events", help="Also write the UI events table (.csv or .parquet)."),
    bundle: Path | None = typer.Option(
        None,
        "--bundle",
        help="Write every table (trials, reports, questionnaires, quiz, sessions, events) in CSV and Parquet, "
        "the study's configuration and a data dictionary into this new (or empty) folder.",
    ),
    pilot: bool = typer.Option(False, "--pilot", help="Include the pilot sessions (left out by default)."),
    as_json: bool = SummaryJsonOpt,
) -> None:
    sqlite = _check_existing_sqlite(db)
    if out is None and bundle is None:
        raise TrustseekError(["give --out FILE (the trial log) or --bundle DIR (every table)"])
    outputs = ((out, "--out", (".csv", ".parquet")), (events, "--events", (".csv", ".parquet")))
    check_outputs(*outputs, inputs=((sqlite, "--db SQLite file"),))
    check_output(bundle, "--bundle", directory=True)
    from ..server.db import open_database  # after the checks: they load the server
    from ..server.export import bundle_files, events_frame, trials_frame, write_bundle, write_frame

    with open_database(db)() as s:
        st = _stored_study(s, study, db)
        trials = trials_frame(s, st, pilot=pilot)
        ev = events_frame(s, st, pilot) if events is not None else None
        files = bundle_files(s, st, pilot) if bundle is not None else {}
    write_atomic(out, lambda tmp: write_frame(trials, tmp))
    write_atomic(events, lambda tmp: write_frame(ev, tmp))
    write_atomic(bundle, lambda tmp: write_bundle(files, tmp), directory=True)
    summary = {
        "study": study,
        "trials": len(trials),
        "participants": int(trials["participant"].nunique()),
        "out": None if out is None else str(out),
        "events": None if ev is None else len(ev),
        "events_out": None if events is None else str(events),
        "bundle": None if bundle is None else str(bundle),
        "files": None if bundle is None else sorted(files),
    }
    if as_json:
        print_json(summary)
        return
    where = [str(p) for p in (out, bundle) if p is not None]
    console.print(
        f"wrote {summary['trials']} trials of {summary['participants']} participants to {' and '.join(where)}"
        + (f"; {summary['events']} events to {events}" if events is not None else "")
    )


def _stored_study(s, study: str, db: str):
    from ..server.orm import Study

    st = s.get(Study, study)
    if st is None:
        raise TrustseekError([f"no study {study!r} in {db}"])
    return st


@command("study")
def study_cmd(
    study: str = StudyArg,
    db: str = StudyDbOpt,
    status: str | None = typer.Option(
        None, "--status", help="Move the study to open, paused or closed (a draft opens; a closed study stays closed)."
    ),
    as_json: bool = SummaryJsonOpt,
) -> None:
    from ..server.db import open_database
    from ..server.errors import Refused
    from ..server.lifecycle import STATUSES, progress, set_status

    _check_existing_sqlite(db)
    if status is not None and status not in STATUSES:
        raise TrustseekError([f"--status {status!r}: expected one of {', '.join(STATUSES)}"])
    with open_database(db)() as s:
        st = _stored_study(s, study, db)
        if status is not None:
            try:
                set_status(s, st, status)
            except Refused as exc:
                raise TrustseekError([f"--status {status}: {exc.message}"]) from None
        counts = progress(s, st.id)
        summary = {"study": st.id, "name": st.name, "status": st.status, "link_path": f"/join/{st.link_token}"}
        summary["sessions"] = counts
    if as_json:
        print_json(summary)
        return
    console.print(f"study {st.id} ({st.name}): {summary['status']}; study link path {summary['link_path']}")
    console.print("  sessions: " + ", ".join(f"{v} {k}" for k, v in counts.items()))
