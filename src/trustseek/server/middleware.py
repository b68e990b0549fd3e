"""ASGI middleware of the experiment server: response timing and the request log.

Both are plain ASGI wrappers (no per-request objects beyond a closure), so the latency-critical
decision API pays next to nothing for them.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

log = logging.getLogger(__name__)

#: path parameters that are credentials: never logged
SECRET_PARAMS = frozenset({"token"})


class ServerTiming:
    """Every response carries ``Server-Timing: app;dur=<ms>``, the time from the request reaching
    the application to its response headers (routing, authentication, validation, the handler
    with its database transaction, serialization)."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        t0 = time.perf_counter()

        async def timed(message: Message) -> None:
            if message["type"] == "http.response.start":
                dur = f"app;dur={(time.perf_counter() - t0) * 1000:.3f}".encode()
                message["headers"] = [*message.get("headers", ()), (b"server-timing", dur)]
            await send(message)

        await self.app(scope, receive, timed)


def request_context(scope: Scope) -> str:
    """``METHOD /route/{template}`` and the path parameters that identify what was asked for
    (study, session, trial), never a token: the template, not the path, is logged because a
    participant's link carries its token in the path."""
    route = getattr(scope.get("route"), "path", None) or "(no route)"
    params = {k: v for k, v in (scope.get("path_params") or {}).items() if k not in SECRET_PARAMS}
    where = "".join(f" {k}={v}" for k, v in params.items())
    return f"{scope.get('method', '?')} {route}{where}"


class RequestLog:
    """Logs refused requests (4xx, at INFO), failed ones (5xx, at ERROR) and unhandled errors
    with the request's context; successful requests are not logged."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)

        async def logged(message: Message) -> None:
            if message["type"] == "http.response.start" and message["status"] >= 400:
                status = message["status"]
                log.log(logging.ERROR if status >= 500 else logging.INFO, "%s -> %d", request_context(scope), status)
            await send(message)

        try:
            await self.app(scope, receive, logged)
        except Exception as exc:
            # the traceback is the ASGI server's to print; this line says which request it was
            log.error("%s failed: %s: %s", request_context(scope), type(exc).__name__, exc)
            raise
