"""One POST straight into an ASGI application, without a server or a socket: the tests of the
decision API's lean path and of many robots at once call the application object this way."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any


async def asgi_post(
    app: Callable[..., Awaitable[None]],
    path: str,
    body: bytes,
    headers: dict[str, str | None],
    *,
    disconnect: bool = True,
    scope_extra: dict[str, Any] | None = None,
) -> tuple[int, dict[bytes, bytes], bytes]:
    """(status, response headers, body) of ``POST path`` with ``body`` and ``headers`` (a value of
    None leaves the header out).  After the body, the client disconnects (``disconnect``) or
    waits, as a client still holding the connection open does."""
    head = [(b"host", b"test")] + [(k.encode(), v.encode()) for k, v in headers.items() if v is not None]
    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": path,
        "raw_path": path.encode(),
        "query_string": b"",
        "root_path": "",
        "headers": head,
        "client": ("127.0.0.1", 1),
        "server": ("127.0.0.1", 80),
        **(scope_extra or {}),
    }
    out: dict[str, Any] = {"status": None, "headers": {}, "body": b""}
    sent = False

    async def receive():
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        if disconnect:
            return {"type": "http.disconnect"}
        await asyncio.sleep(3600)

    async def send(message):
        if message["type"] == "http.response.start":
            out["status"] = message["status"]
            out["headers"] = dict(message["headers"])
        else:
            out["body"] += message.get("body", b"")

    await app(scope, receive, send)
    return out["status"], out["headers"], out["body"]
