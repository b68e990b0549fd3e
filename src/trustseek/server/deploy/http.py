"""The decision API over HTTP: one answer per request (``answer``), served in plain ASGI in front
of FastAPI (``DeployFront``).

Under many robots at once the server's capacity is its CPU time per request, and most of it
went to the framework, not to the decision (measured in process, with the same ``answer``:
0.24-0.26 ms of CPU per request through FastAPI's routing, dependency solving and pydantic,
0.10-0.11 ms in plain ASGI).  So
``decide`` and ``observe`` are answered by ``DeployFront``, the outermost layer of the
application (``app.ServerApp``), whenever:

* the path is ``/api/deploy/sessions/{id}/decide`` or ``.../observe``;
* the bearer token is the token of that deploy session (the check of ``middleware.BodyGuard``
  and the routes), and the declared body length is within ``SESSION_BODY_LIMIT`` (the body is
  read only then);
* the body is JSON (``Content-Type: application/json``) that the route's model, ``DecideIn`` or
  ``ObserveIn``, accepts (validated by that model, as FastAPI would).

It answers successes and the session's refusals (400, 404, 409: the server's domain errors,
``..errors``, given their status by the one mapping, ``middleware.STATUS``) alike.  Anything else -- a malformed body,
another token, a body above the limit -- is handed, body and all, to FastAPI, which refuses it
(401, 403, 413, 422: ``middleware.BodyGuard`` and pydantic) or, for a body its validation takes,
calls the same ``answer`` (``routes``).  Both return the same bytes, with the ``Server-Timing``
header of ``middleware.RequestLog``.

``answer`` runs the request first from the session's state this process knows, with one
conditional write (``store.Known``; on PostgreSQL one statement, awaited), else in one
transaction of ``store.DeployStore`` that reads the session.
"""

from __future__ import annotations

import json
import logging
import secrets
import time
from collections.abc import Callable
from typing import Any

from pydantic import ValidationError

from ..auth import Caller, bearer_token, caller_for_token
from ..errors import Refused, TooLarge
from ..middleware import (
    SESSION_BODY_LIMIT,
    ASGIApp,
    Receive,
    Scope,
    Send,
    read_body,
    refusal,
    refuse,
    replaying,
    status_of,
)
from ..schemas import DecideIn, ObserveIn
from ..sessions import trial_dict
from .service import deploy_decide, deploy_observe
from .store import Known, Stale, Statements

log = logging.getLogger(__name__)

PREFIX = "/api/deploy/sessions/"
_JSON = (b"content-type", b"application/json")

#: (trial, complexity, remaining, visible) of ``decide``; (trial, human action, outcome) of ``observe``
Args = tuple[Any, ...]


def _dump(out: dict[str, Any]) -> bytes:
    return json.dumps(out, allow_nan=False, separators=(",", ":")).encode()


def _request(plans: Any, sid: str, what: str, args: Args) -> Callable[[Statements], dict[str, Any]]:
    if what == "decide":
        return lambda tx: deploy_decide(tx, plans, sid, *args)

    def observe(tx: Statements) -> dict[str, Any]:
        t, dup = deploy_observe(tx, plans, sid, *args)
        return {"trial": t, "duplicate": dup, "belief": t["belief_after"]}

    return observe


async def answer(state: Any, sid: str, what: str, args: Args) -> tuple[int, bytes]:
    """(status, body) of ``what`` (``decide`` or ``observe``) of deploy session ``sid`` with
    ``args`` (``decide_args`` / ``observe_args``), the caller holding the session's token.

    First from the session's state as this process knows it, with one conditional write
    (``store.Known``: one statement on PostgreSQL, awaited on the event loop); when that cannot
    answer, in a transaction that reads the session (``store.DeployStore.transaction``), tried
    again once on a new connection when the database fails."""
    store = state.deploy_store
    run = _request(state.deploy_plans, sid, what, args)
    try:
        known = Known(store)
        out = run(known)
        if known.write is not None and await store.apply_async(known.write):
            return 200, _dump(out)
    except (Stale, Refused):
        pass  # the transaction below reads the session
    except Exception as exc:
        log.debug("deploy %s of session %s: conditional write failed: %s: %s", what, sid, type(exc).__name__, exc)
    for attempt in (1, 2):
        try:
            with store.transaction() as tx:
                return 200, _dump(run(tx))
        except Refused as exc:
            return refusal(exc)
        except store.IntegrityError:
            if what != "observe":
                raise
            with store.transaction() as tx:  # the trial was committed by a concurrent request meanwhile
                old = tx.committed(sid, args[0])
            if old is None:
                raise
            t = trial_dict(old)
            return 200, _dump({"trial": t, "duplicate": True, "belief": t["belief_after"]})
        except store.Error as exc:
            if attempt == 2:
                raise
            log.warning("deploy %s of session %s: database error, tried again: %s: %s", what, sid, type(exc).__name__, exc)
    raise AssertionError("unreachable")


class DeployFront:
    """See the module's docstring; ``app`` is the FastAPI application."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        path = scope.get("path", "") if scope["type"] == "http" else ""
        if scope.get("method") != "POST" or not path.startswith(PREFIX):
            return await self.app(scope, receive, send)
        t0 = time.perf_counter()
        sid, _, what = path[len(PREFIX) :].partition("/")
        if not sid or what not in ("decide", "observe"):
            return await self.app(scope, receive, send)
        caller = _caller(scope, sid)
        if caller is None:
            return await self.app(scope, receive, send)  # nothing read: the guard and the routes answer
        try:
            body = await read_body(receive, SESSION_BODY_LIMIT)  # its declared length is within the limit
        except TooLarge as exc:  # more than declared: the HTTP server refuses such a body before this
            return await refuse(send, status_of(exc), exc.message)
        if body is None:  # the client went away
            return
        args = _args(what, body)
        if args is not None:
            status, out = await answer(scope["app"].state, caller.id, what, args)
            if status >= 400:
                log.info("POST %s{session_id}/%s session_id=%s -> %d", PREFIX, what, caller.id, status)
            timing = b"app;dur=%.3f" % ((time.perf_counter() - t0) * 1000)
            head = [(b"content-length", b"%d" % len(out)), _JSON, (b"server-timing", timing)]
            await send({"type": "http.response.start", "status": status, "headers": head})
            await send({"type": "http.response.body", "body": out})
            return
        await self.app(scope, replaying(body, receive), send)


def _args(what: str, raw: bytes) -> Args | None:
    """The request's arguments, validated by the route's own model (``DecideIn``, ``ObserveIn``),
    or None when that model refuses the body, or it holds a NUL character (the body guard's 400):
    FastAPI then answers it."""
    if b"\\u0000" in raw:
        return None
    try:
        if what == "decide":
            d = DecideIn.model_validate_json(raw)
            return d.trial, d.complexity, d.remaining, d.visible
        o = ObserveIn.model_validate_json(raw)
        return o.trial, o.human_action, o.outcome
    except ValidationError:
        return None


def _caller(scope: Scope, sid: str) -> Caller | None:
    """The deploy session ``sid`` if the request's bearer token is its token, its body is
    declared as JSON and its declared length is within the session limit; else None."""
    auth = kind = length = None
    for k, v in scope.get("headers") or ():
        if k == b"authorization":
            if auth is not None:
                return None
            auth = v
        elif k == b"content-type":
            if kind is not None:
                return None
            kind = v
        elif k == b"content-length":
            if length is not None:
                return None
            length = v
    if auth is None or kind is None or length is None or kind.split(b";")[0].strip().lower() != b"application/json":
        return None
    if not length.isdigit() or int(length) > SESSION_BODY_LIMIT:
        return None
    token = bearer_token(auth.decode("latin-1"))
    if token is None:
        return None
    caller = caller_for_token(scope["app"].state, token)
    if caller is None or caller.kind != "deploy" or not secrets.compare_digest(caller.id.encode(), sid.encode()):
        return None
    return caller
