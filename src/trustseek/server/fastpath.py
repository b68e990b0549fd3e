"""The decision API's lean path: ``decide`` and ``observe`` of a deploy session answered in
plain ASGI, before FastAPI's routing, dependency solving and pydantic validation.

Under many robots at once the server's capacity is its CPU time per request, and most of it
went to the framework, not to the decision.  This wrapper is the outermost layer
of the application (``app.ServerApp``) and answers a request itself only when it is a
well-formed request that succeeds:

* the path is ``/api/deploy/sessions/{id}/decide`` or ``.../observe``;
* the bearer token is the token of that deploy session (the check of ``middleware.BodyGuard``
  and the routes), and the declared body length is within ``SESSION_BODY_LIMIT`` (the body is
  read only then);
* the body is JSON (``Content-Type: application/json``) holding only the fields of
  ``DecideIn`` (without the schedule fields) or ``ObserveIn``, with exactly the types and
  bounds those models accept;
* the decision (``deploy.deploy_decide`` / ``deploy_observe``, the same functions the routes
  call) succeeds, committed: from the session's state this process knows, with one conditional
  write (``store.Known``; on PostgreSQL one statement, awaited), or else in one transaction of
  ``store.DeployStore`` that reads the session.

Anything else -- a malformed or unusual body, another token, a refusal of the session's state,
a database error -- is rolled back (nothing is written) and handed to the full application
with the body replayed, which answers exactly as it always has (the refusals, their bodies and
the 422 validation errors are FastAPI's, after the same guard).  Both paths return the same
bytes for a success, with the ``Server-Timing`` header of ``middleware.ServerTiming``.
"""

from __future__ import annotations

import json
import logging
import secrets
import time
from collections.abc import Callable
from typing import Any

from .auth import Caller, caller_for_token
from .deploy import deploy_decide, deploy_observe
from .middleware import SESSION_BODY_LIMIT, ASGIApp, Message, Receive, Scope, Send
from .schemas import MAX_TRIAL
from .sessions import SessionError
from .store import Known, Stale, Statements

log = logging.getLogger(__name__)

PREFIX = "/api/deploy/sessions/"
_DECIDE = frozenset({"trial", "complexity", "remaining", "visible"})
_OBSERVE = frozenset({"trial", "human_action", "outcome"})
_HUMAN = frozenset({"intervene", "rely"})
_OUTCOME = frozenset({"success", "failure", "collision", "dropped", "teleoperated"})
_JSON = (b"content-type", b"application/json")


def _trial(body: dict[str, Any]) -> int | None:
    n = body.get("trial")
    return n if type(n) is int and 1 <= n <= MAX_TRIAL else None


def _decide_args(body: dict[str, Any]) -> tuple[int, str | None] | None:
    """(trial, complexity) of a body ``DecideIn`` accepts without the schedule fields, else None."""
    if not body.keys() <= _DECIDE or body.get("remaining") is not None or body.get("visible") is not None:
        return None
    n, c = _trial(body), body.get("complexity")
    if n is None or not (c is None or (type(c) is str and 1 <= len(c) <= 32)):
        return None
    return n, c


def _observe_args(body: dict[str, Any]) -> tuple[int, str | None, str | None] | None:
    """(trial, human action, outcome) of a body ``ObserveIn`` accepts, else None."""
    if not body.keys() <= _OBSERVE:
        return None
    n, h, o = _trial(body), body.get("human_action"), body.get("outcome")
    if n is None or not (h is None or (type(h) is str and h in _HUMAN)) or not (o is None or (type(o) is str and o in _OUTCOME)):
        return None
    return n, h, o


def _dump(out: dict[str, Any]) -> bytes:
    # as routes._json
    return json.dumps(out, allow_nan=False, separators=(",", ":")).encode()


class DeployFastPath:
    """See the module's docstring; ``app`` is the full application."""

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
        chunks = []
        while True:
            message = await receive()
            if message["type"] != "http.request":  # the client went away
                return
            chunks.append(message.get("body", b""))
            if not message.get("more_body"):
                break
        body = b"".join(chunks)
        out = await answer(scope["app"].state, caller.id, what, body)
        if out is not None:
            timing = b"app;dur=%.3f" % ((time.perf_counter() - t0) * 1000)
            head = [(b"content-length", b"%d" % len(out)), _JSON, (b"server-timing", timing)]
            await send({"type": "http.response.start", "status": 200, "headers": head})
            await send({"type": "http.response.body", "body": out})
            return
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)


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
    scheme, _, token = auth.decode("latin-1").partition(" ")
    token = token.strip()
    if scheme.lower() != "bearer" or not token:
        return None
    caller = caller_for_token(scope["app"].state, token)
    if caller is None or caller.kind != "deploy" or not secrets.compare_digest(caller.id.encode(), sid.encode()):
        return None
    return caller


async def answer(state: Any, sid: str, what: str, raw: bytes) -> bytes | None:
    """The response body of a request this path answers (``what`` is ``decide`` or
    ``observe`` of deploy session ``sid``, whose token the request carries), or None to hand it on.

    First from the session's state as this process knows it, with one conditional write
    (``store.Known``: one statement on PostgreSQL, awaited on the event loop); when that cannot
    answer, in a transaction that reads the session (``store.DeployStore.transaction``)."""
    try:
        body = json.loads(raw)
    except (ValueError, RecursionError):  # the full application refuses it (middleware.json_body_problem)
        return None
    if type(body) is not dict:
        return None
    run = _request(what, sid, body)
    if run is None:
        return None
    store = state.deploy_store
    try:
        known = Known(store)
        out = run(known)
        if known.write is not None and await store.apply_async(known.write):
            return _dump(out)
    except (Stale, SessionError):
        pass  # the transaction below reads the session
    except Exception as exc:
        log.debug("deploy %s of session %s: conditional write failed: %s: %s", what, sid, type(exc).__name__, exc)
    try:
        with store.transaction() as tx:
            out = run(tx)
        return _dump(out)
    except SessionError:
        return None  # rolled back: the full application answers the refusal
    except Exception as exc:
        log.debug("deploy %s of session %s handed to the full application: %s: %s", what, sid, type(exc).__name__, exc)
        return None


def _request(what: str, sid: str, body: dict[str, Any]) -> Callable[[Statements], dict[str, Any]] | None:
    """The request as a function of the statements it runs with, or None when the body is one
    this path does not answer."""
    if what == "decide":
        args = _decide_args(body)
        if args is None:
            return None
        n, complexity = args
        return lambda tx: deploy_decide(tx, sid, n, complexity)
    oargs = _observe_args(body)
    if oargs is None:
        return None

    def observe(tx: Statements) -> dict[str, Any]:
        t, dup = deploy_observe(tx, sid, *oargs)
        return {"trial": t, "duplicate": dup, "belief": t["belief_after"]}

    return observe
