"""The FastAPI application factory: ``create_app(db_url, token)``."""

from __future__ import annotations

import secrets
import time
from pathlib import Path

from fastapi import FastAPI, HTTPException
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles

from ..version import __version__
from .db import DEFAULT_URL, open_database
from .routes import deploy, experimenter, own, participant

STATIC = Path(__file__).resolve().parent.parent / "static" / "app"


class ServerTiming:
    """ASGI middleware: every response carries ``Server-Timing: app;dur=<ms>``, the time from
    the request reaching the application to its response headers (routing, authentication,
    validation, the handler with its database transaction, serialization)."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        t0 = time.perf_counter()

        async def timed(message):
            if message["type"] == "http.response.start":
                dur = f"app;dur={(time.perf_counter() - t0) * 1000:.3f}".encode()
                message["headers"] = [*message.get("headers", ()), (b"server-timing", dur)]
            await send(message)

        await self.app(scope, receive, timed)


def create_app(db_url: str = DEFAULT_URL, token: str | None = None, public_url: str | None = None) -> FastAPI:
    """The experiment server.  ``token`` guards the experimenter endpoints (a random one is
    made when not given: read it from ``app.state.token``).  Migrations run here, before
    the first request."""
    app = FastAPI(
        title="trustseek experiment server",
        version=__version__,
        description="Human-in-the-loop experiments with a live assistance-seeking policy, and a decision API for robots.",
    )
    app.state.db = open_database(db_url)
    app.state.engine = app.state.db.kw["bind"]
    app.state.token = token or secrets.token_urlsafe(24)
    app.state.public_url = public_url
    app.state.tokens = {}  # session token -> Caller
    app.add_middleware(ServerTiming)
    app.include_router(deploy)  # first: the decision API is matched without trying the others
    app.include_router(experimenter)
    app.include_router(own)
    app.include_router(participant)

    def page(name: str) -> FileResponse:
        path = STATIC / name
        if not path.exists():
            raise HTTPException(503, "the web front end is not built: run scripts/setup.sh (npm ci && npm run build in web/)")
        return FileResponse(path, media_type="text/html", headers={"Cache-Control": "no-store", "Referrer-Policy": "no-referrer"})

    @app.get("/s/{token}", include_in_schema=False)
    def participant_page(token: str):
        return page("participant.html")

    @app.get("/dashboard", include_in_schema=False)
    def dashboard_page():
        return page("dashboard.html")

    @app.get("/", include_in_schema=False)
    def index():
        return RedirectResponse("/dashboard")

    @app.get("/api/health", tags=["meta"])
    def health():
        return {"status": "ok", "version": __version__}

    if STATIC.exists():
        app.mount("/static/app", StaticFiles(directory=STATIC), name="static")
    else:

        @app.get("/static/app/{path:path}", include_in_schema=False)
        def no_static(path: str):
            return HTMLResponse("front end not built", status_code=503)

    return app
