"""The FastAPI application factory: ``create_app(db_url, token)``."""

from __future__ import annotations

import gc
import logging
import os
import secrets
from typing import Any

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.concurrency import run_in_threadpool

from ..model.jsonfile import json_safe
from ..version import __version__
from .cache import Bounded, StudyCaches
from .db import DEFAULT_URL, open_database, safe_url
from .deploy.http import DeployFront, deploy
from .deploy.store import DeployStore
from .errors import Refused
from .link_routes import STATIC, lifecycle, pages, static_page
from .middleware import BodyGuard, RequestLog, refusal
from .participant_routes import own, participant
from .plan import Plans
from .preview import Previews
from .routes import experimenter
from .schemas import ErrorOut
from .studies import more_problems

log = logging.getLogger(__name__)


async def refused(request: Request, exc: Exception) -> Response:
    """A refusal of the session layers (``errors.Refused``) with its HTTP status, as ``HTTPException``'s."""
    assert isinstance(exc, Refused)
    status, body = refusal(exc)
    return Response(body, status_code=status, media_type="application/json")


async def validation_error(request: Request, exc: Exception) -> JSONResponse:
    """422 with every problem, as FastAPI answers, a refused ``NaN`` or infinity echoed as
    ``null`` (``model.jsonfile.json_safe``; FastAPI's own answer would fail to serialise, a 500)."""
    assert isinstance(exc, RequestValidationError)
    errors = list(exc.errors())
    if request.method == "POST" and request.url.path == "/api/studies":
        # a study's other problems too, not only its fields' (solving a policy may take a moment)
        more = await run_in_threadpool(more_problems, exc.body, errors)
        errors += [{"type": "study", "loc": ["body"], "msg": p} for p in more]
    return JSONResponse(status_code=422, content={"detail": json_safe(jsonable_encoder(errors))})


class ServerApp(FastAPI):
    """The FastAPI application behind the decision API's front (``deploy.http.DeployFront``)."""

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self._front = DeployFront(super().__call__)

    async def __call__(self, scope, receive, send) -> None:
        scope["app"] = self  # as Starlette sets it
        await self._front(scope, receive, send)


#: every route may refuse a NUL character in its path, query or JSON body (``middleware.BodyGuard``)
NUL_REFUSAL: dict[int | str, dict[str, Any]] = {
    400: {
        "model": ErrorOut,
        "description": "The request is not allowed (a NUL character in its path, query or a string of its body).",
    }
}


#: the garbage collector's thresholds of a server process (Python's default: 700, 10, 10)
GC_THRESHOLDS = (20_000, 20, 50)


def settle_memory() -> None:
    """Keep the garbage collector's pauses out of request latencies, in a server process once its
    application is built: what start-up made is moved out of the collector's passes
    (``gc.freeze``), and the young generation is collected after 20,000 net allocations instead
    of 700 (a decision API request frees what it allocates), a full pass every ~20 million."""
    gc.collect()
    gc.freeze()
    gc.set_threshold(*GC_THRESHOLDS)


#: the environment variables :func:`from_environment` reads (``trustseek serve --workers N`` sets them)
ENV_DB, ENV_TOKEN, ENV_PUBLIC_URL = "TRUSTSEEK_DB", "TRUSTSEEK_TOKEN", "TRUSTSEEK_PUBLIC_URL"
#: the previews' database that the worker processes share (``preview.Previews``)
ENV_PREVIEW_DB = "TRUSTSEEK_PREVIEW_DB"


def from_environment() -> FastAPI:
    """The server configured by the environment (``ENV_*``): the application each worker process
    of ``trustseek serve --workers N`` builds."""
    token = os.environ.get(ENV_TOKEN)
    if not token:
        raise RuntimeError(f"${ENV_TOKEN} is not set")
    app = create_app(
        os.environ.get(ENV_DB, DEFAULT_URL),
        token=token,
        public_url=os.environ.get(ENV_PUBLIC_URL) or None,
        preview_url=os.environ.get(ENV_PREVIEW_DB) or None,
    )
    settle_memory()
    return app


def create_app(
    db_url: str = DEFAULT_URL, token: str | None = None, public_url: str | None = None, preview_url: str | None = None
) -> FastAPI:
    """The experiment server.  ``token`` guards the experimenter endpoints (by default a random
    one, ``app.state.token``).  Migrations run here.  Previews run in a database of their own
    (``preview_url``, by default a temporary file: ``preview.Previews``)."""
    app = ServerApp(
        title="trustseek experiment server",
        version=__version__,
        description="Human-in-the-loop experiments with a live assistance-seeking policy, and a decision API for robots.",
    )
    app.state.db = open_database(db_url)
    app.state.engine = app.state.db.kw["bind"]
    app.state.token = token or secrets.token_urlsafe(24)
    app.state.public_url = public_url
    app.state.tokens = Bounded(100_000)  # session token -> auth.Caller
    # what the application remembers is the application's: nothing is cached in a module
    app.state.deploy_store = DeployStore(app.state.engine)  # the decision API's connections and sessions' live rows
    app.state.deploy_plans = Plans()  # the deploy sessions' plans, one parsed copy per content
    app.state.study_caches = StudyCaches()  # the studies' configurations and policies ...
    app.state.db.configure(info={"caches": app.state.study_caches})  # ... reached from the database sessions
    app.state.previews = Previews(app.state.study_caches, preview_url)  # previews' rows: never in the study's database
    app.router.add_event_handler("shutdown", app.state.deploy_store.close)  # its connections end with the server
    app.router.add_event_handler("shutdown", app.state.previews.close)
    app.add_exception_handler(RequestValidationError, validation_error)
    app.add_exception_handler(Refused, refused)
    app.add_middleware(BodyGuard)
    app.add_middleware(RequestLog)
    # deploy first: the decision API is matched without trying the others
    for router in (deploy, experimenter, own, participant, lifecycle, pages):
        app.include_router(router, responses=NUL_REFUSAL)

    @app.get("/dashboard", include_in_schema=False)
    def dashboard_page():
        return static_page("dashboard.html")

    @app.get("/", include_in_schema=False)
    def index():
        return RedirectResponse("/dashboard")

    @app.get("/api/health", tags=["meta"])
    def health():
        return {"status": "ok", "version": __version__}

    log.info("trustseek %s experiment server: database %s", __version__, safe_url(db_url))
    if STATIC.exists():
        app.mount("/static/app", StaticFiles(directory=STATIC), name="static")
    else:
        log.warning("the web front end is not built (%s is missing): run scripts/setup.sh", STATIC)

        @app.get("/static/app/{path:path}", include_in_schema=False)
        def no_static(path: str):
            return HTMLResponse("front end not built", status_code=503)

    return app
