"""The deploy sessions' live state on the database driver's own connection (``sqlite3`` or
``psycopg``), held by the process: SQLAlchemy's pooling, caches and result objects cost several
times what the database spends on the decision API's one short write by primary key.

A request is answered from the state this process knows (``Known``, the usual way: one write
conditional on the row still holding that state; on PostgreSQL one statement, awaited on the
event loop on connections of its own), or else in a transaction that reads the row (``BEGIN
IMMEDIATE`` on SQLite, ``SELECT ... FOR UPDATE`` on PostgreSQL) with the same statements: when
the process does not know the session or another process has moved it on, and for anything
that writes nothing.  Both commit before the response is sent.  A connection that fails is
dropped and the next use opens a new one.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import json
import re
import threading
from collections.abc import Iterator
from datetime import datetime
from types import SimpleNamespace
from typing import Any, NamedTuple

from sqlalchemy.engine import Engine

from ...errors import TrustseekError
from ..cache import Bounded
from ..orm import TRIAL_FIELDS, Trial


class LiveRow(NamedTuple):
    """A deploy session's live columns (``belief`` as a list)."""

    id: str
    kind: str
    seed: int
    belief: list
    trials_done: int
    score: float
    pending_trial: int | None = None
    pending_complexity: str | None = None
    pending_action: str | None = None


_INSERTED = ("session_id", *TRIAL_FIELDS, "practice", "created_at")

# written with :name parameters (PostgreSQL's rewritten to %(name)s); the writes change the row
# only if it still holds what they were computed from (see ``Known``)
_SQL = {
    "live": f"SELECT {', '.join(LiveRow._fields)} FROM sessions WHERE id = :sid{{lock}}",
    "committed": f"SELECT {', '.join(TRIAL_FIELDS)} FROM trials WHERE session_id = :sid AND trial = :n",
    "plan": "SELECT plan FROM sessions WHERE id = :sid",
    "policy": "SELECT policy FROM policies WHERE sha256 = :sha",
    "insert": f"INSERT INTO trials ({', '.join(_INSERTED)}) VALUES ({', '.join(':' + c for c in _INSERTED)})",
    "decided": "UPDATE sessions SET pending_trial = :p_trial, pending_complexity = :p_complexity, "
    "pending_action = :p_action, updated_at = :now WHERE id = :sid AND trials_done = :was AND pending_trial IS NULL",
    "observed": "UPDATE sessions SET belief = {belief_json}, trials_done = :done, score = :score, pending_trial = NULL, "
    "pending_complexity = NULL, pending_action = NULL, updated_at = :now WHERE id = :sid AND trials_done = :was "
    "AND pending_trial = :done AND pending_complexity = :p_complexity AND pending_action = :p_action",
}


def _statements(dialect: str) -> dict[str, str]:
    if dialect == "sqlite":
        return {k: v.format(lock="", belief_json=":belief_json") for k, v in _SQL.items()}
    from sqlalchemy.dialects import postgresql

    out = {k: v.format(lock=" FOR UPDATE", belief_json="CAST(:belief_json AS JSON)") for k, v in _SQL.items()}
    # observe in one statement: the trial is inserted only if the session row was advanced (a
    # parameter in a SELECT list has no type of its own: each is cast to its column's)
    pg, column = postgresql.dialect(), Trial.__table__.c
    values = ", ".join(
        "advanced.id" if c == "session_id" else f"CAST(:{c} AS {column[c].type.compile(dialect=pg)})" for c in _INSERTED
    )
    out["observed"] = (
        f"WITH advanced AS ({out['observed']} RETURNING id) "
        f"INSERT INTO trials ({', '.join(_INSERTED)}) SELECT {values} FROM advanced"
    )
    return {k: re.sub(r":([a-z_]+)", r"%(\1)s", v) for k, v in out.items()}


def _json_value(v: Any) -> Any:
    return json.loads(v) if isinstance(v, str | bytes) else v


class Stale(TrustseekError):
    """The state this process knows of a session cannot answer the request by a conditional
    write alone: it runs in a transaction that reads the session instead (never seen by a client)."""


class Write(NamedTuple):
    """A request's conditional write: the statement, its parameters, the session's live columns
    once it has been applied, and (SQLite) the trial inserted once the row has advanced."""

    sql: str
    params: dict[str, Any]
    after: LiveRow
    insert: dict[str, Any] | None


def _decided(store: DeployStore, row: LiveRow, n: int, complexity: str, action: str, now: datetime) -> Write:
    params = {"sid": row.id, "was": row.trials_done, "p_trial": n, "p_complexity": complexity, "p_action": action}
    after = row._replace(pending_trial=n, pending_complexity=complexity, pending_action=action)
    return Write(store.sql["decided"], {**params, "now": store.now(now)}, after, None)


def _observed(store: DeployStore, row: LiveRow, trial: dict[str, Any], belief: list, score: float, now: datetime) -> Write:
    """Advance the session by the committed ``trial`` (``trial_dict``'s keys) and insert it."""
    t, n = store.now(now), trial["trial"]
    params = {"sid": row.id, "was": row.trials_done, "done": n, "score": score, "now": t, "belief_json": json.dumps(belief)}
    params.update(p_complexity=row.pending_complexity, p_action=row.pending_action)
    inserted = {**trial, "session_id": row.id, "practice": False, "created_at": t}
    after = LiveRow(row.id, row.kind, row.seed, list(belief), n, score)
    if store.sqlite:
        return Write(store.sql["observed"], params, after, inserted)
    return Write(store.sql["observed"], {**inserted, **params}, after, None)  # one statement


MAX_KNOWN = 200_000  # sessions whose state is remembered (the least recently used forgotten first)
ASYNC_CONNECTIONS = 8  # PostgreSQL: connections for conditional writes awaited on the event loop


class DeployStore:
    """The decision API's statements on one held driver connection: ``with store.transaction()
    as tx:`` runs ``tx.live(...)`` and the others in one transaction (committed when the block
    ends without an exception); ``apply_async`` applies a ``Known`` request's write.  A lock
    serializes the held connection's use (for applications driven from several threads)."""

    def __init__(self, engine: Engine):
        self.engine = engine
        self.sqlite = engine.dialect.name == "sqlite"
        self.sql = _statements(engine.dialect.name)
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

    def now(self, t: datetime) -> Any:
        # SQLite: SQLAlchemy's storage format of a DateTime column (microseconds always written)
        return t.strftime("%Y-%m-%d %H:%M:%S.%f") if self.sqlite else t

    @contextlib.contextmanager
    def transaction(self) -> Iterator[DeployStore]:
        with self._lock:
            self._seen = None
            try:
                self._cursor().execute("BEGIN IMMEDIATE" if self.sqlite else "BEGIN")
            except BaseException:
                self._drop()  # a closed or broken connection: the next transaction opens another
                raise
            try:
                yield self
                self._fairy.driver_connection.commit()
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
            if self._seen is not None:
                self.remember(self._seen)

    def _one(self, what: str, **params: Any) -> Any:
        self._cur.execute(self.sql[what], params)
        return self._cur.fetchone()

    def live(self, sid: str) -> LiveRow | None:
        row = self._one("live", sid=sid)
        if row is None:
            return None
        self._seen = LiveRow(*row)._replace(belief=_json_value(row[3]))
        return self._seen

    def committed(self, sid: str, n: int) -> Any:
        """Trial ``n`` of the session (its ``TRIAL_FIELDS`` as attributes), or None."""
        row = self._one("committed", sid=sid, n=n)
        return None if row is None else SimpleNamespace(**dict(zip(TRIAL_FIELDS, row, strict=True)))

    def plan(self, sid: str) -> dict[str, Any] | None:
        row = self._one("plan", sid=sid)
        return None if row is None else _json_value(row[0])

    def policy(self, sha: str) -> dict[str, Any]:
        row = self._one("policy", sha=sha)
        if row is None:
            raise LookupError(f"no stored policy {sha}")
        return _json_value(row[0])

    def decided(self, sid: str, n: int, complexity: str, action: str, now: datetime) -> None:
        assert self._seen is not None and self._seen.id == sid
        self._run(_decided(self, self._seen, n, complexity, action, now))

    def observed(self, sid: str, trial: dict[str, Any], belief: list, score: float, now: datetime) -> None:
        assert self._seen is not None and self._seen.id == sid
        self._run(_observed(self, self._seen, trial, belief, score, now))

    def _run(self, w: Write) -> bool:
        """Run a write on the held connection (the row read in the transaction holds what it was
        computed from): whether it changed the row."""
        self._cur.execute(w.sql, w.params)
        done = self._cur.rowcount == 1
        if done and w.insert is not None:
            self._cur.execute(self.sql["insert"], w.insert)
        self._seen = w.after if done else None
        return done

    def _settle(self, w: Write, done: bool) -> bool:
        if done:
            self.remember(w.after)
        else:
            self.known.pop(w.after.id)
        return done

    async def apply_async(self, w: Write) -> bool:
        """Apply and commit a conditional write: whether the session was still in the state it was
        computed from.  On SQLite on the held connection; on PostgreSQL awaited on one of up to
        ``ASYNC_CONNECTIONS`` connections of its own (waiting for one when all are busy), so that
        other requests are served meanwhile and commits made at once share the log's flushes."""
        if self.sqlite:
            with self._lock:
                try:
                    self._cursor().execute("BEGIN IMMEDIATE")
                    done = self._run(w)
                    self._fairy.driver_connection.commit()
                except BaseException:
                    self.known.pop(w.after.id)
                    with contextlib.suppress(Exception):
                        self._fairy.driver_connection.rollback()
                    self._drop()
                    raise
            return self._settle(w, done)
        conn = await self._checkout()
        try:
            if conn is None:
                conn = await self._connect_async()
            cur = conn.cursor()
            await cur.execute(w.sql, w.params)
            done = cur.rowcount == 1
        except BaseException:
            self.known.pop(w.after.id)
            if conn is not None:
                with contextlib.suppress(Exception):
                    conn.pgconn.finish()
            self._checkin(None)
            raise
        self._checkin(conn)
        return self._settle(w, done)

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


class Known:
    """A ``decide`` or ``observe`` answered from the session's live columns as this process last
    read or committed them, its one write deferred (``write``) for ``DeployStore.apply_async``.
    A session's row only moves forward (``trials_done`` grows, the belief and score change only
    with it, a pending decision is set once and cleared with its trial), so a write conditional
    on those columns is one that a locked read would have made.  A read of a trial, the plan or a
    policy raises ``Stale``: only a transaction that reads the row answers those."""

    def __init__(self, store: DeployStore):
        self.store = store
        self.row: LiveRow | None = None
        self.write: Write | None = None

    def live(self, sid: str) -> LiveRow | None:
        self.row = self.store.known.get(sid)
        if self.row is None:
            raise Stale(f"session {sid}: not known here")
        return self.row

    def committed(self, *args: Any) -> Any:
        raise Stale(f"{args[0]}: answered only after a read")

    plan = policy = committed

    def decided(self, sid: str, n: int, complexity: str, action: str, now: datetime) -> None:
        assert self.row is not None and self.row.id == sid and self.write is None
        self.write = _decided(self.store, self.row, n, complexity, action, now)

    def observed(self, sid: str, trial: dict[str, Any], belief: list, score: float, now: datetime) -> None:
        assert self.row is not None and self.row.id == sid and self.write is None
        self.write = _observed(self.store, self.row, trial, belief, score, now)


#: what the decision API's functions (``service.deploy_decide`` and the others) run with
Statements = DeployStore | Known
