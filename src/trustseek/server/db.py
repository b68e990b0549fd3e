"""Database connection and start-up migrations.

``open_database(url)`` creates the engine (SQLite file by default, PostgreSQL by URL) and
brings the schema to the newest Alembic revision before anything else touches it.
"""

from __future__ import annotations

import sqlite3
import threading
import time
import urllib.parse
import weakref
from pathlib import Path

from alembic import command
from alembic.config import Config
from sqlalchemy import create_engine, event, make_url
from sqlalchemy.engine import Engine
from sqlalchemy.orm import sessionmaker

from ..errors import TrustseekError

MIGRATIONS = Path(__file__).resolve().parent / "migrations"
DEFAULT_URL = "sqlite:///trustseek.sqlite"
#: seconds a PostgreSQL server may take to answer a new connection (one that accepts and never
#: answers is refused after this, with one line, instead of a wait without end)
CONNECT_TIMEOUT = 10


class DatabaseError(TrustseekError):
    """The database URL is unusable or the database cannot be reached."""


def _sqlite_pragmas(dbapi_connection, _record) -> None:
    # transactions are begun explicitly (see _sqlite_begin), not by the driver; WAL + NORMAL:
    # committed trials survive a killed process; checkpoints run in a background thread
    # (_checkpoint_in_background), the automatic ones are only a backstop
    dbapi_connection.isolation_level = None
    cur = dbapi_connection.cursor()
    for pragma in ("journal_mode=WAL", "synchronous=NORMAL", "foreign_keys=ON", "busy_timeout=10000"):
        cur.execute(f"PRAGMA {pragma}")
    cur.execute(f"PRAGMA wal_autocheckpoint={BACKSTOP_CHECKPOINT_PAGES}")
    cur.close()


BACKSTOP_CHECKPOINT_PAGES = 4000  # ~16 MB of log: reached only under sustained writes with no pause
CHECKPOINT_INTERVAL = 0.5  # seconds


def _checkpoint_in_background(engine: Engine) -> None:
    """In WAL mode SQLite copies the log back into the database file (a *checkpoint*, which
    waits for the disk) inside whichever commit makes the log cross a size, 1000 pages by
    default: that request, and every request queued behind it, would wait for the disk.  Here
    a daemon thread runs a PASSIVE checkpoint (it never blocks readers or writers) twice a
    second instead, on its own connection; automatic checkpoints remain only as a backstop for
    a very long log.  The thread ends when the engine is gone."""
    path = engine.url.database
    if not path or path == ":memory:" or path.startswith("file:"):
        return
    uri = "file:" + urllib.parse.quote(str(Path(path).resolve())) + "?mode=rw"  # never create the file
    ref = weakref.ref(engine)

    def run() -> None:
        con = None
        while ref() is not None:
            time.sleep(CHECKPOINT_INTERVAL)
            try:
                con = con or sqlite3.connect(uri, uri=True, timeout=1.0, isolation_level=None, check_same_thread=False)
                con.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchall()
            except sqlite3.Error:  # removed, or busy: try again later
                if con is not None:
                    con.close()
                con = None
        if con is not None:
            con.close()

    threading.Thread(target=run, name="trustseek-sqlite-checkpoint", daemon=True).start()


def _sqlite_begin(conn) -> None:
    """BEGIN IMMEDIATE: a transaction takes SQLite's write lock at its start, so concurrent
    requests on one session serialize (the second sees the first's commit) instead of failing
    with a stale snapshot."""
    conn.exec_driver_sql("BEGIN IMMEDIATE")


def driver_url(url: str) -> str:
    """``postgresql://`` (or ``postgres://``) without a driver means psycopg 3, the driver
    trustseek depends on (SQLAlchemy's own default would be psycopg2)."""
    for scheme in ("postgresql://", "postgres://"):
        if url.startswith(scheme):
            return "postgresql+psycopg://" + url[len(scheme) :]
    return url


def make_engine(url: str) -> Engine:
    url = driver_url(url)
    try:
        if url.startswith("sqlite"):
            engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 10}, pool_size=20, max_overflow=20)
            event.listen(engine, "connect", _sqlite_pragmas)
            event.listen(engine, "begin", _sqlite_begin)
            _checkpoint_in_background(engine)
        else:
            connect = {"connect_timeout": CONNECT_TIMEOUT} if url.startswith("postgresql+psycopg") else {}
            engine = create_engine(url, pool_pre_ping=True, pool_size=20, max_overflow=20, connect_args=connect)
    except Exception as exc:  # any driver or URL problem becomes one clear line
        raise DatabaseError([f"cannot use database URL {safe_url(url)!r}: {_first_line(exc)}"]) from None
    return engine


def migrate(engine: Engine) -> None:
    """Upgrade the schema to the newest revision (idempotent)."""
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    try:
        with engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "head")
    except Exception as exc:
        raise DatabaseError(
            [f"cannot migrate database {engine.url.render_as_string(hide_password=True)}: {_first_line(exc)}"]
        ) from None


def safe_url(url: str) -> str:
    """The database URL without its password, fit for logs and messages."""
    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:
        return url.split("@")[-1]


def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def offline_sql(url: str) -> str:
    """The migration SQL for a database URL's dialect, without connecting (``alembic --sql``)."""
    import io

    buf = io.StringIO()
    cfg = Config(output_buffer=buf)
    cfg.set_main_option("script_location", str(MIGRATIONS))
    cfg.set_main_option("sqlalchemy.url", url)
    command.upgrade(cfg, "head", sql=True)
    return buf.getvalue()


def open_database(url: str = DEFAULT_URL) -> sessionmaker:
    engine = make_engine(url)
    migrate(engine)
    return sessionmaker(engine, expire_on_commit=False)
