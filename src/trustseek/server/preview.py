"""Previews: the experimenter's look at a study's participant view, run without recording.

A preview session runs the participant's routes and logic, but its rows live in a database of
their own (``app.state.previews``; by default a temporary SQLite file removed when the server
stops, shared by the worker processes through ``$TRUSTSEEK_PREVIEW_DB``), so a preview never
reaches an export, a count or the balancing of block orders.  At most ``MAX_PREVIEWS`` are
kept; older ones are forgotten (their links then answer 404).
"""

from __future__ import annotations

import secrets
import shutil
import tempfile
import threading
import weakref
from pathlib import Path

from sqlalchemy import delete, select
from sqlalchemy.orm import Session as DBSession
from sqlalchemy.orm import sessionmaker

from .cache import StudyCaches
from .db import open_database
from .lifecycle import create_participant
from .orm import Answer, Event, EventBatch, Report, Session, Study, Trial, token_session

MAX_PREVIEWS = 50
#: the tables holding a session's rows, removed with a forgotten preview
_ROWS = (Event, EventBatch, Trial, Report, Answer)


class Previews:
    """The preview sessions of one server, in their own database (``url``; by default a
    temporary SQLite file made on first use and removed with this object)."""

    def __init__(self, caches: StudyCaches, url: str | None = None):
        self._caches = caches
        self._url = url
        self._db: sessionmaker | None = None
        self._dir: str | None = None
        self._lock = threading.Lock()

    def _database(self, create: bool) -> sessionmaker | None:
        with self._lock:
            if self._db is None:
                if self._url is None:
                    if not create:
                        return None
                    self._dir = tempfile.mkdtemp(prefix="trustseek-previews-")  # owner-only (0700)
                    weakref.finalize(self, shutil.rmtree, self._dir, True)
                    self._url = f"sqlite:///{Path(self._dir) / 'previews.sqlite'}"
                elif not create and not Path(self._url.removeprefix("sqlite:///")).exists():
                    return None  # no worker has made a preview yet
                self._db = open_database(self._url)
                self._db.configure(info={"caches": self._caches})
            return self._db

    def db(self) -> DBSession:
        """A database session on the previews' database."""
        made = self._database(create=True)
        assert made is not None
        return made()

    def find(self, token: str) -> tuple[str, str] | None:
        """(session id, kind) of a preview's token, or None."""
        made = self._database(create=False)
        if made is None:
            return None
        with made() as db:
            return token_session(db, token)

    def start(self, study: Study) -> Session:
        """A new preview session of ``study`` (copied into the previews' database as it is now)."""
        with self.db() as db:
            db.merge(Study(id=study.id, name=study.name, config=study.config, status=study.status, link_token=None))
            db.flush()
            s = create_participant(db, db.get_one(Study, study.id), f"preview-{secrets.token_hex(4)}", role="preview")
            db.commit()
            self._forget_old(db)
            return s

    def _forget_old(self, db: DBSession) -> None:
        old = db.scalars(select(Session.id).order_by(Session.created_at.desc()).offset(MAX_PREVIEWS)).all()
        if old:
            for table in _ROWS:
                db.execute(delete(table).where(table.session_id.in_(old)))
            db.execute(delete(Session).where(Session.id.in_(old)))
            db.commit()

    def close(self) -> None:
        """Close the previews' database (its temporary file is removed with this object)."""
        with self._lock:
            if self._db is not None:
                self._db.kw["bind"].dispose()
                self._db = None
            if self._dir is not None:
                shutil.rmtree(self._dir, ignore_errors=True)
                self._dir, self._url = None, None
