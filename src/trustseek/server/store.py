"""The deploy sessions' live state on one held database connection, without an ORM.

The decision API is the latency-critical path: each request is one short transaction of a
handful of statements by primary key.  Going through SQLAlchemy (a pooled connection checked
out and in, statement compilation-cache lookups, result objects, events) costs several times
what the database itself spends, so this store runs those statements on the driver's own
connection (``sqlite3`` or ``psycopg``), held by the process and reused:

* the statements are written once per dialect and prepared by the driver (``sqlite3`` keeps a
  per-connection statement cache; ``psycopg`` prepares a statement on the server once it has
  run a few times);
* a transaction is ``BEGIN IMMEDIATE`` (SQLite: the write lock is taken at the start, so
  concurrent requests on one session, from any process, serialize) or a ``SELECT ... FOR
  UPDATE`` of the session row (PostgreSQL), and is committed before the response is sent: what
  the server acknowledged is on disk (WAL) and survives a killed process;
* the session's state is read inside every transaction, never cached: with several worker
  processes a session's requests may reach any of them, and a primary-key read inside the
  transaction that is open anyway costs less than any check that a cached copy is current.
  What never changes (a session's task, model and parsed policy) is cached by ``sessions``.

A lock serializes the transactions of one process (the event loop runs them one at a time
anyway; the lock matters only when the application is driven from several threads, as test
clients do).  A connection that fails is dropped and the next transaction opens a new one.
"""

from __future__ import annotations

import contextlib
import json
import threading
from collections.abc import Iterator
from datetime import datetime
from typing import Any, NamedTuple

from sqlalchemy.engine import Engine


class LiveRow(NamedTuple):
    """A deploy session's live columns (``belief`` as a list)."""

    id: str
    kind: str
    seed: int
    belief: list
    trials_done: int
    score: float
    pending_trial: int | None
    pending_complexity: str | None
    pending_action: str | None


class TrialRow(NamedTuple):
    """A committed trial's columns, as ``trial_dict`` reads them."""

    trial: int
    block: int
    policy: str
    complexity: str
    robot_action: str
    human_action: str | None
    outcome: str
    experience: str
    reward: float
    belief: float | None
    belief_after: float | None
    effort_ms: float | None
    submission_id: str


_TRIAL_COLUMNS = ", ".join(TrialRow._fields)
_INSERTED = ("session_id", *TrialRow._fields, "practice", "created_at")

# written with :name parameters; PostgreSQL's are rewritten to %(name)s below
_SQL = {
    "live": "SELECT id, kind, seed, belief, trials_done, score, pending_trial, pending_complexity, pending_action "
    "FROM sessions WHERE id = :sid{lock}",
    "committed": f"SELECT {_TRIAL_COLUMNS} FROM trials WHERE session_id = :sid AND trial = :n",
    "decided": "UPDATE sessions SET pending_trial = :p_trial, pending_complexity = :p_complexity, "
    "pending_action = :p_action, updated_at = :now WHERE id = :sid",
    "observed": "UPDATE sessions SET belief = {belief}, trials_done = :done, score = :score, pending_trial = NULL, "
    "pending_complexity = NULL, pending_action = NULL, updated_at = :now WHERE id = :sid",
    "insert": f"INSERT INTO trials ({', '.join(_INSERTED)}) VALUES ({', '.join(':' + c for c in _INSERTED)})",
    "plan": "SELECT plan FROM sessions WHERE id = :sid",
    "policy": "SELECT policy FROM policies WHERE sha256 = :sha",
}


def _statements(dialect: str) -> dict[str, str]:
    if dialect == "sqlite":
        return {k: v.format(lock="", belief=":belief") for k, v in _SQL.items()}
    import re

    out = {k: v.format(lock=" FOR UPDATE", belief="CAST(:belief AS JSON)") for k, v in _SQL.items()}
    return {k: re.sub(r":([a-z_]+)", r"%(\1)s", v) for k, v in out.items()}


def _sqlite_time(t: datetime) -> str:
    # SQLAlchemy's storage format of a DateTime column in SQLite (microseconds always written)
    return t.strftime("%Y-%m-%d %H:%M:%S.%f")


def _json_value(v: Any) -> Any:
    return json.loads(v) if isinstance(v, str | bytes) else v


class DeployStore:
    """The statements of the decision API on one held driver connection (see the module's
    docstring).  ``with store.transaction() as tx:`` runs ``tx.live(...)`` and the others in one
    transaction, committed when the block ends without an exception, rolled back otherwise."""

    def __init__(self, engine: Engine):
        self.engine = engine
        self.dialect = engine.dialect.name
        self.sqlite = self.dialect == "sqlite"
        self.sql = _statements(self.dialect)
        dbapi = engine.dialect.dbapi
        assert dbapi is not None
        #: the driver's exceptions: a unique-constraint violation, and any database error
        self.IntegrityError: type[Exception] = dbapi.IntegrityError
        self.Error: type[Exception] = dbapi.Error
        self._reconnect: tuple[type[Exception], ...] = (dbapi.OperationalError, dbapi.InterfaceError)
        self._lock = threading.Lock()
        self._fairy: Any = None  # the pool's wrapper of the held connection
        self._cur: Any = None

    def _cursor(self) -> Any:
        if self._cur is None:
            self._fairy = self.engine.raw_connection()
            self._cur = self._fairy.driver_connection.cursor()
        return self._cur

    def _drop(self) -> None:
        """Forget the held connection (closed, not returned to the pool)."""
        fairy, self._fairy, self._cur = self._fairy, None, None
        if fairy is not None:
            with contextlib.suppress(Exception):
                fairy.invalidate()

    def close(self) -> None:
        with self._lock:
            self._drop()

    @contextlib.contextmanager
    def transaction(self) -> Iterator[DeployStore]:
        with self._lock:
            try:
                cur = self._cursor()
                if self.sqlite:
                    cur.execute("BEGIN IMMEDIATE")
            except BaseException:
                self._drop()  # a closed or broken connection: the next transaction opens another
                raise
            try:
                yield self
            except BaseException as exc:
                try:
                    self._fairy.driver_connection.rollback()
                except Exception:
                    self._drop()
                else:
                    if isinstance(exc, self._reconnect):
                        self._drop()
                raise
            try:
                self._fairy.driver_connection.commit()
            except BaseException:
                self._drop()
                raise

    def _now(self, t: datetime) -> Any:
        return _sqlite_time(t) if self.sqlite else t

    # ------------------------------------------------------------------ statements

    def live(self, sid: str) -> LiveRow | None:
        self._cur.execute(self.sql["live"], {"sid": sid})
        row = self._cur.fetchone()
        if row is None:
            return None
        row = LiveRow(*row)
        return row._replace(belief=_json_value(row.belief))

    def committed(self, sid: str, n: int) -> TrialRow | None:
        self._cur.execute(self.sql["committed"], {"sid": sid, "n": n})
        row = self._cur.fetchone()
        return None if row is None else TrialRow(*row)

    def decided(self, sid: str, n: int, complexity: str, action: str, now: datetime) -> None:
        self._cur.execute(
            self.sql["decided"], {"sid": sid, "p_trial": n, "p_complexity": complexity, "p_action": action, "now": self._now(now)}
        )

    def observed(self, sid: str, trial: dict[str, Any], belief: list, score: float, now: datetime) -> None:
        """Insert the committed ``trial`` (``trial_dict``'s keys) and advance the session."""
        t = self._now(now)
        self._cur.execute(self.sql["insert"], {**trial, "session_id": sid, "practice": False, "created_at": t})
        self._cur.execute(
            self.sql["observed"], {"sid": sid, "belief": json.dumps(belief), "done": trial["trial"], "score": score, "now": t}
        )

    def plan(self, sid: str) -> dict[str, Any] | None:
        self._cur.execute(self.sql["plan"], {"sid": sid})
        row = self._cur.fetchone()
        return None if row is None else _json_value(row[0])

    def policy(self, sha: str) -> dict[str, Any]:
        self._cur.execute(self.sql["policy"], {"sha": sha})
        row = self._cur.fetchone()
        if row is None:
            raise LookupError(f"no stored policy {sha}")
        return _json_value(row[0])
