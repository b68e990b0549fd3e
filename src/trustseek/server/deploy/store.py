"""The deploy sessions' live state on the database driver's own connections, without an ORM.

The decision API is the latency-critical path: each request is one short write by primary key.
Going through SQLAlchemy (a pooled connection checked out and in, statement compilation-cache
lookups, result objects, events) costs several times what the database itself spends, so this
store runs its statements on the driver's own connection (``sqlite3`` or ``psycopg``), held by
the process and reused; the statements are written once per dialect and prepared by the driver
(``sqlite3`` keeps a per-connection statement cache; ``psycopg`` prepares a statement on the
server once it has run a few times).

A request is answered in one of two ways, both committed before the response is sent (what the
server acknowledged is in the database's log and survives a killed server process):

* **From the known state** (``Known``), the usual way: the process keeps each session's live
  columns as it last committed or read them (``DeployStore.known``), computes the answer from
  them, and makes its one write conditional on the row still holding them
  (``UPDATE ... WHERE id = ... AND trials_done = ... AND pending_trial ...``).  On PostgreSQL
  that is one statement per request (an observation's trial is inserted by the same statement,
  ``WITH advanced AS (UPDATE ... RETURNING id) INSERT ... SELECT ... FROM advanced``), committed
  by itself, and awaited on the event loop on a few connections of its own (``apply_async``),
  so the process serves other requests while PostgreSQL works and concurrent commits share
  PostgreSQL's flushes of its log.  With several worker processes a session's requests may
  reach any of them: a row another process has moved on fails the condition, nothing is
  written, and the request runs in a transaction instead.
* **In a transaction** that reads the row: ``BEGIN IMMEDIATE`` (SQLite: the write lock is taken
  at the start, so concurrent requests on one session, from any process, serialize) or
  ``BEGIN`` and ``SELECT ... FOR UPDATE`` of the session row (PostgreSQL), on the held
  connection: when the process does not know the session or its known state is out of date,
  and for everything that writes nothing (a repeated request, a refusal).

A lock serializes the use of the held connection (the event loop runs its transactions one at
a time anyway; the lock matters only when the application is driven from several threads, as
test clients do).  A connection that fails is dropped and the next use opens a new one.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import json
import threading
from collections.abc import Iterator
from datetime import datetime
from typing import Any, NamedTuple, Protocol

from sqlalchemy.engine import Engine

from ...errors import TrustseekError
from ..cache import Bounded
from ..orm import Trial, TrialRow


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
    # the conditional writes of a request answered from the state this process knows (``Known``):
    # they change the row only if it is still in that state (see ``Known``)
    "decided_if": "UPDATE sessions SET pending_trial = :p_trial, pending_complexity = :p_complexity, "
    "pending_action = :p_action, updated_at = :now WHERE id = :sid AND trials_done = :was AND pending_trial IS NULL",
    "observed_if": "UPDATE sessions SET belief = {belief_json}, trials_done = :done, score = :score, pending_trial = NULL, "
    "pending_complexity = NULL, pending_action = NULL, updated_at = :now WHERE id = :sid AND trials_done = :was "
    "AND pending_trial = :done AND pending_complexity = :p_complexity AND pending_action = :p_action",
    "policy": "SELECT policy FROM policies WHERE sha256 = :sha",
}


def _statements(dialect: str) -> dict[str, str]:
    if dialect == "sqlite":
        return {k: v.format(lock="", belief=":belief", belief_json=":belief_json") for k, v in _SQL.items()}
    import re

    from sqlalchemy.dialects import postgresql

    out = {
        k: v.format(lock=" FOR UPDATE", belief="CAST(:belief AS JSON)", belief_json="CAST(:belief_json AS JSON)")
        for k, v in _SQL.items()
    }
    # observe in one statement: the trial is inserted only if the session row was advanced (a
    # parameter in a SELECT list has no type of its own: each is cast to its column's)
    pg = postgresql.dialect()
    column = Trial.__table__.c
    values = ", ".join(
        "advanced.id" if c == "session_id" else f"CAST(:{c} AS {column[c].type.compile(dialect=pg)})" for c in _INSERTED
    )
    out["observed_if"] = (
        f"WITH advanced AS ({out['observed_if']} RETURNING id) "
        f"INSERT INTO trials ({', '.join(_INSERTED)}) SELECT {values} FROM advanced"
    )
    return {k: re.sub(r":([a-z_]+)", r"%(\1)s", v) for k, v in out.items()}


def _sqlite_time(t: datetime) -> str:
    # SQLAlchemy's storage format of a DateTime column in SQLite (microseconds always written)
    return t.strftime("%Y-%m-%d %H:%M:%S.%f")


def _json_value(v: Any) -> Any:
    return json.loads(v) if isinstance(v, str | bytes) else v


class Statements(Protocol):
    """What the decision API's functions (``deploy.deploy_decide`` and the others) run their
    request with: ``DeployStore`` in a transaction, or ``Known``."""

    def live(self, sid: str) -> LiveRow | None: ...

    def committed(self, sid: str, n: int) -> TrialRow | None: ...

    def decided(self, sid: str, n: int, complexity: str, action: str, now: datetime) -> None: ...

    def observed(self, sid: str, trial: dict[str, Any], belief: list, score: float, now: datetime) -> None: ...

    def plan(self, sid: str) -> dict[str, Any] | None: ...

    def policy(self, sha: str) -> dict[str, Any]: ...


class Stale(TrustseekError):
    """The state this process knows of a session cannot answer the request by a conditional
    write alone: the request runs in a transaction that reads the session instead (never seen
    by a client)."""


class Write(NamedTuple):
    """A request's conditional write (``Known``): the statement, its parameters, and the
    session's live columns once it has been applied."""

    sql: str
    params: dict[str, Any]
    after: LiveRow
    insert: dict[str, Any] | None  # SQLite: the trial inserted once the row has advanced


MAX_KNOWN = 200_000  # sessions whose state is remembered (the least recently used forgotten first)
ASYNC_CONNECTIONS = 8  # PostgreSQL: connections for conditional writes awaited on the event loop


class DeployStore:
    """The statements of the decision API on one held driver connection (see the module's
    docstring).  ``with store.transaction() as tx:`` runs ``tx.live(...)`` and the others in one
    transaction, committed when the block ends without an exception, rolled back otherwise.
    ``Known(store)`` answers from the state this process knows instead, with one conditional
    write applied by ``apply`` or ``apply_async``."""

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
        #: session id -> its live columns as this process last read or committed them
        self.known: Bounded[str, LiveRow] = Bounded(MAX_KNOWN)
        self._seen: LiveRow | None = None  # the transaction's session, as it will be after the commit
        self._idle: list[Any] = []  # PostgreSQL: idle connections of apply_async
        self._opened = 0  # ... and those in use
        self._waiters: collections.deque[asyncio.Future] = collections.deque()  # requests waiting for one

    def _cursor(self) -> Any:
        if self._cur is None:
            self._fairy = self.engine.raw_connection()
            if not self.sqlite:  # transactions are begun explicitly; a conditional write commits itself
                self._fairy.driver_connection.autocommit = True
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
            idle, self._idle = self._idle, []
            for conn in idle:
                with contextlib.suppress(Exception):
                    conn.pgconn.finish()

    def remember(self, row: LiveRow) -> None:
        """Record a session's live columns as just committed (a session opened by this process)."""
        self.known.put(row.id, row)

    def _settle(self, sid: str, after: LiveRow | None) -> None:
        if after is None:
            self.known.pop(sid)
        else:
            self.remember(after)

    @contextlib.contextmanager
    def transaction(self) -> Iterator[DeployStore]:
        with self._lock:
            self._seen = None
            try:
                cur = self._cursor()
                cur.execute("BEGIN IMMEDIATE" if self.sqlite else "BEGIN")
            except BaseException:
                self._drop()  # a closed or broken connection: the next transaction opens another
                raise
            try:
                yield self
            except BaseException as exc:
                if self._seen is not None:
                    self.known.pop(self._seen.id)
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
                if self._seen is not None:
                    self.known.pop(self._seen.id)
                self._drop()
                raise
            if self._seen is not None:
                self.remember(self._seen)

    def _now(self, t: datetime) -> Any:
        return _sqlite_time(t) if self.sqlite else t

    # ------------------------------------------------------------------ statements

    def live(self, sid: str) -> LiveRow | None:
        self._cur.execute(self.sql["live"], {"sid": sid})
        row = self._cur.fetchone()
        if row is None:
            return None
        row = LiveRow(*row)
        row = self._seen = row._replace(belief=_json_value(row.belief))
        return row

    def committed(self, sid: str, n: int) -> TrialRow | None:
        self._cur.execute(self.sql["committed"], {"sid": sid, "n": n})
        row = self._cur.fetchone()
        return None if row is None else TrialRow(*row)

    def decided(self, sid: str, n: int, complexity: str, action: str, now: datetime) -> None:
        self._cur.execute(
            self.sql["decided"], {"sid": sid, "p_trial": n, "p_complexity": complexity, "p_action": action, "now": self._now(now)}
        )
        if self._seen is not None:
            self._seen = self._seen._replace(pending_trial=n, pending_complexity=complexity, pending_action=action)

    def observed(self, sid: str, trial: dict[str, Any], belief: list, score: float, now: datetime) -> None:
        """Insert the committed ``trial`` (``trial_dict``'s keys) and advance the session."""
        t = self._now(now)
        self._cur.execute(self.sql["insert"], {**trial, "session_id": sid, "practice": False, "created_at": t})
        self._cur.execute(
            self.sql["observed"], {"sid": sid, "belief": json.dumps(belief), "done": trial["trial"], "score": score, "now": t}
        )
        if self._seen is not None:
            self._seen = _advanced(self._seen, trial["trial"], belief, score)

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

    # ------------------------------------------------------------------ conditional writes

    def apply(self, w: Write) -> bool:
        """Apply a conditional write on the held connection: True if the session was still in
        the state it was computed from (the write is then committed), else False (nothing written)."""
        sid = w.params["sid"]
        with self._lock:
            try:
                cur = self._cursor()
                if self.sqlite:
                    cur.execute("BEGIN IMMEDIATE")
                    cur.execute(w.sql, w.params)
                    done = cur.rowcount == 1
                    if done and w.insert is not None:
                        cur.execute(self.sql["insert"], w.insert)
                    self._fairy.driver_connection.commit()
                else:
                    cur.execute(w.sql, w.params)  # one statement, committed by itself
                    done = cur.rowcount == 1
            except BaseException:
                self.known.pop(sid)
                with contextlib.suppress(Exception):
                    self._fairy.driver_connection.rollback()
                self._drop()
                raise
        self._settle(sid, w.after if done else None)
        return done

    async def apply_async(self, w: Write) -> bool:
        """``apply``, awaited on the event loop (PostgreSQL), on one of up to ``ASYNC_CONNECTIONS``
        connections of its own, so that other requests are served while the database works
        (and commits made at once share PostgreSQL's flushes of its log); when all of them are
        busy, the request waits for one.  On SQLite, ``apply`` (in process: nothing to wait for)."""
        if self.sqlite:
            return self.apply(w)
        sid = w.params["sid"]
        conn = await self._checkout()
        try:
            if conn is None:
                conn = await self._connect_async()
            cur = conn.cursor()
            await cur.execute(w.sql, w.params)
            done = cur.rowcount == 1
        except BaseException:
            self.known.pop(sid)
            if conn is not None:
                with contextlib.suppress(Exception):
                    conn.pgconn.finish()
            self._checkin(None)
            raise
        self._checkin(conn)
        self._settle(sid, w.after if done else None)
        return done

    async def _checkout(self) -> Any:
        """An idle connection of ``apply_async``, or None: open one (a free place)."""
        with self._lock:
            if self._idle:
                return self._idle.pop()
            if self._opened < ASYNC_CONNECTIONS:
                self._opened += 1
                return None
            waiter = asyncio.get_running_loop().create_future()
            self._waiters.append(waiter)
        try:
            return await waiter
        except BaseException:  # cancelled
            with self._lock, contextlib.suppress(ValueError):
                self._waiters.remove(waiter)
            if waiter.done() and not waiter.cancelled():  # handed over just before: pass it on
                self._checkin(waiter.result())
            raise

    def _checkin(self, conn: Any) -> None:
        """Give back a connection (None: its place, the connection having been closed) to the
        first waiting request, else to the idle ones."""
        with self._lock:
            if self._waiters:
                waiter = self._waiters.popleft()
                waiter.get_loop().call_soon_threadsafe(self._hand, waiter, conn)
            elif conn is None:
                self._opened -= 1
            else:
                self._idle.append(conn)

    def _hand(self, waiter: asyncio.Future, conn: Any) -> None:
        if waiter.done():  # the request went away meanwhile: the next one gets it
            self._checkin(conn)
        else:
            waiter.set_result(conn)

    async def _connect_async(self) -> Any:
        import psycopg

        cargs, cparams = self.engine.dialect.create_connect_args(self.engine.url)
        return await psycopg.AsyncConnection.connect(*cargs, autocommit=True, **cparams)


def _advanced(row: LiveRow, n: int, belief: list, score: float) -> LiveRow:
    return row._replace(
        belief=list(belief), trials_done=n, score=score, pending_trial=None, pending_complexity=None, pending_action=None
    )


class Known:
    """A ``decide`` or ``observe`` answered from the session's live columns as this process
    last read or committed them (``DeployStore.known``), without reading them: the request's
    one write is made conditional on the row still holding what it was computed from, and
    deferred (``write``) to be applied by ``DeployStore.apply`` / ``apply_async``.

    A session's row only moves forward: ``trials_done`` only grows, the belief and score change
    only with it, and a pending decision for the next trial is set once and cleared only when
    that trial is committed.  So a row with the known ``trials_done`` and pending trial (and,
    for an observation, the pending decision) holds the known belief and score as well, and a
    write conditional on those columns is a write that a locked read would have made.  When the
    row has moved on (another process served the session) the write changes nothing and the
    request runs in a transaction instead.  Anything else than the one write -- an answer that
    writes nothing (a repeated request), a read of a trial, the plan or a policy, a refusal --
    raises ``Stale`` or is not applied: only a transaction that reads the row answers those."""

    def __init__(self, store: DeployStore):
        self.store = store
        self.row: LiveRow | None = None
        self.write: Write | None = None

    def live(self, sid: str) -> LiveRow | None:
        row = self.row = self.store.known.get(sid)
        if row is None:
            raise Stale(f"session {sid}: not known here")
        return row

    def committed(self, sid: str, n: int) -> TrialRow | None:
        raise Stale(f"session {sid}: answered only after a read")

    def plan(self, sid: str) -> dict[str, Any] | None:
        raise Stale(f"session {sid}: answered only after a read")

    def policy(self, sha: str) -> dict[str, Any]:
        raise Stale(f"policy {sha}: answered only after a read")

    def decided(self, sid: str, n: int, complexity: str, action: str, now: datetime) -> None:
        row = self.row
        assert row is not None and row.id == sid and self.write is None
        params = {
            "sid": sid,
            "was": row.trials_done,
            "p_trial": n,
            "p_complexity": complexity,
            "p_action": action,
            "now": self.store._now(now),
        }
        after = row._replace(pending_trial=n, pending_complexity=complexity, pending_action=action)
        self.write = Write(self.store.sql["decided_if"], params, after, None)

    def observed(self, sid: str, trial: dict[str, Any], belief: list, score: float, now: datetime) -> None:
        row = self.row
        assert row is not None and row.id == sid and self.write is None
        t = self.store._now(now)
        n = trial["trial"]
        params = {
            "sid": sid,
            "was": row.trials_done,
            "done": n,
            "p_complexity": row.pending_complexity,
            "p_action": row.pending_action,
            "belief_json": json.dumps(belief),
            "score": score,
            "now": t,
        }
        inserted = {**trial, "session_id": sid, "practice": False, "created_at": t}
        after = _advanced(row, n, belief, score)
        if self.store.sqlite:
            self.write = Write(self.store.sql["observed_if"], params, after, inserted)
        else:  # one statement: the row advanced and the trial inserted
            self.write = Write(self.store.sql["observed_if"], {**inserted, **params}, after, None)
