"""Plain ASGI middleware of the experiment server (nearly free for the decision API): response
timing with the request log, and the guard that authenticates writes and caps their size before
any body is read; the refusals' status codes."""

from __future__ import annotations

import json
import logging
import re
import secrets
import time
from typing import Any

import numpy as np
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .auth import MISSING_TOKEN, bearer_token, caller_for_token
from .errors import Conflict, Gone, NotAllowed, NotFound, Refused, TooLarge

log = logging.getLogger(__name__)

#: the HTTP status of each refusal of the session layers (``errors``): the one mapping
STATUS: dict[type[Refused], int] = {NotAllowed: 400, NotFound: 404, Conflict: 409, Gone: 410, TooLarge: 413}


def status_of(exc: Refused) -> int:
    """The HTTP status of a refusal (of its class, or the nearest class above it in ``STATUS``)."""
    return next(STATUS[c] for c in type(exc).__mro__ if c in STATUS)


def json_bytes(value: Any) -> bytes:
    """A JSON answer's bytes, as FastAPI's ``JSONResponse`` writes them."""
    return json.dumps(value, ensure_ascii=False, allow_nan=False, separators=(",", ":")).encode("utf-8")


def refusal(exc: Refused) -> tuple[int, bytes]:
    """(status, body) of a refusal: ``{"detail": message}``."""
    return status_of(exc), json_bytes({"detail": exc.message})


def request_context(scope: Scope) -> str:
    """``METHOD /route/{template}`` and the path parameters but a token (the template, not the
    path, as a participant's link carries its token in the path)."""
    route = getattr(scope.get("route"), "path", None) or "(no route)"
    params = {k: v for k, v in (scope.get("path_params") or {}).items() if k != "token"}
    where = "".join(f" {k}={v}" for k, v in params.items())
    return f"{scope.get('method', '?')} {route}{where}"


class RequestLog:
    """Every response carries ``Server-Timing: app;dur=<ms>``, the time from the request reaching
    the application to its response headers.  Refused requests (4xx) are logged at INFO, failed
    ones (5xx) and unhandled errors at ERROR, with the request's context."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        t0 = time.perf_counter()

        async def logged(message: Message) -> None:
            if message["type"] == "http.response.start":
                dur = f"app;dur={(time.perf_counter() - t0) * 1000:.3f}".encode()
                message["headers"] = [*message.get("headers", ()), (b"server-timing", dur)]
                status = message["status"]
                if status >= 400:
                    log.log(logging.ERROR if status >= 500 else logging.INFO, "%s -> %d", request_context(scope), status)
            await send(message)

        try:
            await self.app(scope, receive, logged)
        except Exception as exc:
            # the traceback is the ASGI server's to print; this line says which request it was
            log.error("%s failed: %s: %s", request_context(scope), type(exc).__name__, exc)
            raise


#: the largest request body of a session (participant or robot) and of the experimenter
SESSION_BODY_LIMIT = 256 * 1024
EXPERIMENTER_BODY_LIMIT = 16 * 1024 * 1024
_WRITES = frozenset({"POST", "PUT", "PATCH", "DELETE"})


async def read_body(receive: Receive, send: Send, limit: int) -> bytes | None:
    """A request's whole body, read from ``receive``; None when the client went away first, or
    when the body is longer than ``limit`` bytes (refused with 413 before more is read)."""
    chunks, size = [], 0
    while True:
        message = await receive()
        if message["type"] != "http.request":
            return None
        chunk = message.get("body", b"")
        size += len(chunk)
        if size > limit:
            await too_large(send, limit)
            return None
        chunks.append(chunk)
        if not message.get("more_body"):
            return b"".join(chunks)


def replaying(body: bytes, receive: Receive) -> Receive:
    """A ``receive`` that gives the body read already, then the connection's own messages."""
    given = False

    async def replay() -> Message:
        nonlocal given
        if not given:
            given = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay


async def respond(send: Send, status: int, body: bytes, *headers: tuple[bytes, bytes]) -> None:
    """Send a JSON answer, its headers in the order Starlette writes them."""
    head = [(b"content-length", b"%d" % len(body)), (b"content-type", b"application/json"), *headers]
    await send({"type": "http.response.start", "status": status, "headers": head})
    await send({"type": "http.response.body", "body": body})


async def refuse(send: Send, status: int, detail: str | list[dict[str, Any]], *headers: tuple[bytes, bytes]) -> None:
    await respond(send, status, json_bytes({"detail": detail}), *headers)


async def too_large(send: Send, limit: int) -> None:
    """Refuse a request whose body is longer than ``limit`` bytes (413)."""
    await refuse(send, 413, f"the request body must be at most {limit} bytes")


#: the deepest nesting of arrays and objects a JSON body may have (refused before it is parsed,
#: so that no parser, validator or error message recurses through it)
MAX_JSON_DEPTH = 64
_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_NUL = re.compile(r"(?<!\\)(?:\\\\)*\\u0000")


def json_depth(text: str) -> int:
    """The deepest nesting of arrays and objects in JSON ``text`` (not counting strings)."""
    code = np.frombuffer(_STRING.sub("", text).encode("utf-8", "replace"), dtype=np.uint8)
    step = np.isin(code, _OPEN).astype(np.int64) - np.isin(code, _CLOSE)
    return int(np.cumsum(step).max(initial=0))


_OPEN = np.frombuffer(b"[{", dtype=np.uint8)
_CLOSE = np.frombuffer(b"]}", dtype=np.uint8)


def json_body_problem(headers: dict[bytes, bytes], body: bytes) -> tuple[int, Any] | None:
    """(status, detail) of a body sent as JSON that no route may be given: not text (422), nested
    deeper than ``MAX_JSON_DEPTH`` (422), or holding a NUL character in a string (400:
    PostgreSQL's text cannot hold it, so it is refused on every database); else None."""
    kind = headers.get(b"content-type", b"").split(b";")[0].strip().lower()
    if not body or (kind != b"application/json" and not kind.endswith(b"+json")):
        return None
    try:
        text = body.decode(json.detect_encoding(body))
    except (UnicodeDecodeError, LookupError):
        return 422, [_invalid("the body is not JSON text (UTF-8)")]
    if text.count("[") + text.count("{") > MAX_JSON_DEPTH and json_depth(text) > MAX_JSON_DEPTH:
        return 422, [_invalid(f"the body is nested deeper than {MAX_JSON_DEPTH} levels of arrays and objects")]
    found = _NUL.search(text) if "\\u0000" in text else None
    if found is not None:
        where = f"in a string at character {found.end() - 6}"
        return 400, f"the body holds a NUL character (\\u0000) {where}: text may not contain NUL"
    return None


def _invalid(msg: str) -> dict[str, Any]:
    return {"type": "json_invalid", "loc": ["body"], "msg": msg, "input": None}


class BodyGuard:
    """Every write to ``/api/`` is authenticated before its body is read (no bearer token: 401;
    neither the experimenter's nor a session's: 401 on session paths, 403 elsewhere), then read
    up to the session's or the experimenter's bound (413 beyond, declared or streamed) and
    checked once for every route (``json_body_problem``); the path and query of every request to
    ``/api/`` hold no NUL character.  Which session a token may write to is the routes' check."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not scope.get("path", "").startswith("/api/"):
            return await self.app(scope, receive, send)
        if "\x00" in scope["path"] or b"%00" in scope.get("query_string", b""):
            return await refuse(send, 400, "the path or the query holds a NUL character (%00): text may not contain NUL")
        if scope.get("method") not in _WRITES:
            return await self.app(scope, receive, send)
        state = scope["app"].state
        headers = dict(scope.get("headers") or ())
        token = bearer_token(headers.get(b"authorization", b"").decode("latin-1"))
        if token is None:
            return await refuse(send, 401, MISSING_TOKEN, (b"www-authenticate", b"Bearer"))
        if secrets.compare_digest(token.encode(), state.token.encode()):
            limit = EXPERIMENTER_BODY_LIMIT
        elif caller_for_token(state, token) is not None:
            limit = SESSION_BODY_LIMIT
        else:
            if scope["path"].startswith(("/api/sessions/", "/api/deploy/sessions/")):
                return await refuse(send, 401, "unknown session token")
            return await refuse(send, 403, "wrong experimenter token")
        declared = headers.get(b"content-length")
        if declared is not None and (not declared.isdigit() or int(declared) > limit):
            return await too_large(send, limit)
        body = await read_body(receive, send, limit)
        if body is None:  # refused, or the client went away
            return
        problem = json_body_problem(headers, body)
        if problem is not None:  # (FastAPI would answer an undecodable body with an undocumented 400)
            return await refuse(send, *problem)
        await self.app(scope, replaying(body, receive), send)
