"""The decision API over HTTP: its FastAPI routes, and one answer of ``decide`` and ``observe``
(``answer``) served in plain ASGI in front of FastAPI (``DeployFront``).

Under many robots at once the server's capacity is its CPU time per request, most of which went
to the framework (0.24-0.26 ms per request through FastAPI's routing, dependencies and pydantic,
0.10-0.11 ms in plain ASGI, with the same ``answer``).  So ``DeployFront``, the outermost layer
of the application (``app.ServerApp``), answers a POST to ``/api/deploy/sessions/{id}/decide``
or ``.../observe`` whose bearer token is that deploy session's, whose declared JSON body is
within ``SESSION_BODY_LIMIT`` and accepted by the route's model (``DecideIn``, ``ObserveIn``).
Anything else is handed, body and all, to FastAPI, which refuses it (401, 403, 413, 422) or
calls the same ``answer``: both give the same bytes, with the ``Server-Timing`` header.

``answer`` runs the request first from the session's state this process knows, with one
conditional write (``store.Known``), else in one transaction of ``store.DeployStore``.
"""

from __future__ import annotations

import logging
import secrets
import time
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Request, Response
from pydantic import ValidationError
from sqlalchemy import select
from starlette.types import ASGIApp, Receive, Scope, Send

from ...errors import TrustseekError
from ..auth import (
    Caller,
    bearer,
    bearer_token,
    caller_for_token,
    require_experimenter,
    require_session,
    session_caller,
    token_of,
)
from ..errors import Refused
from ..middleware import SESSION_BODY_LIMIT, json_bytes, read_body, refusal, replaying, respond
from ..orm import Session, Trial
from ..routes import errors
from ..schemas import DecideIn, DeployIn, ObserveIn
from ..sessions import p_high, pending, trial_dict
from ..studies import ConfigError, complexity_problems, load_model_spec, load_task_spec, resolve_policy
from .service import create_deploy, deploy_decide, deploy_observe, score_problems
from .store import Known, LiveRow, Stale, Statements

log = logging.getLogger(__name__)

PREFIX = "/api/deploy/sessions/"

#: (trial, complexity, remaining, visible) of ``decide``; (trial, human action, outcome) of ``observe``
Args = tuple[Any, ...]


def _run(plans: Any, sid: str, what: str, args: Args, tx: Statements) -> dict[str, Any]:
    return deploy_decide(tx, plans, sid, *args) if what == "decide" else _observed(*deploy_observe(tx, plans, sid, *args))


def _observed(t: dict[str, Any], duplicate: bool) -> dict[str, Any]:
    """``observe``'s answer: the committed trial, whether it repeats one, the belief after it."""
    return {"trial": t, "duplicate": duplicate, "belief": t["belief_after"]}


async def answer(state: Any, sid: str, what: str, args: Args) -> tuple[int, bytes]:
    """(status, body) of ``what`` (``decide`` or ``observe``) of deploy session ``sid`` with
    ``args``, the caller holding the session's token: first from the session's state as this
    process knows it, with one conditional write; when that cannot answer, in a transaction
    that reads the session, tried again once on a new connection when the database fails."""
    store, plans = state.deploy_store, state.deploy_plans
    try:
        known = Known(store)
        out = _run(plans, sid, what, args, known)
        if known.write is not None and await store.apply_async(known.write):
            return 200, json_bytes(out)
    except (Stale, Refused):
        pass  # the transaction below reads the session
    except Exception as exc:
        log.debug("deploy %s of session %s: conditional write failed: %s: %s", what, sid, type(exc).__name__, exc)
    for attempt in (1, 2):
        try:
            with store.transaction() as tx:
                return 200, json_bytes(_run(plans, sid, what, args, tx))
        except Refused as exc:
            return refusal(exc)
        except store.IntegrityError:
            if what != "observe":
                raise
            with store.transaction() as tx:  # the trial was committed by a concurrent request meanwhile
                old = tx.committed(sid, args[0])
            if old is None:
                raise
            return 200, json_bytes(_observed(trial_dict(old), True))
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
        caller = _caller(scope, sid) if sid and what in ("decide", "observe") else None
        if caller is None:
            return await self.app(scope, receive, send)  # nothing read: the guard and the routes answer
        # its declared length is within the limit (the HTTP server refuses a body longer than declared)
        body = await read_body(receive, send, SESSION_BODY_LIMIT)
        if body is None:  # refused, or the client went away
            return
        args = _args(what, body)
        if args is None:
            return await self.app(scope, replaying(body, receive), send)
        status, out = await answer(scope["app"].state, caller.id, what, args)
        if status >= 400:
            log.info("POST %s{session_id}/%s session_id=%s -> %d", PREFIX, what, caller.id, status)
        await respond(send, status, out, (b"server-timing", b"app;dur=%.3f" % ((time.perf_counter() - t0) * 1000)))


def _args(what: str, raw: bytes) -> Args | None:
    """The request's arguments, validated by the route's own model, or None when that model
    refuses the body, or it holds a NUL character (the body guard's 400): FastAPI answers it."""
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


_HEADERS = (b"authorization", b"content-type", b"content-length")


def _caller(scope: Scope, sid: str) -> Caller | None:
    """The deploy session ``sid`` if the request's bearer token (one header of each) is its
    token, its body is declared as JSON and its declared length is within the session limit."""
    found: dict[bytes, bytes] = {}
    for k, v in scope.get("headers") or ():
        if k in _HEADERS:
            if k in found:
                return None
            found[k] = v
    auth, kind, length = (found.get(k) for k in _HEADERS)
    if auth is None or kind is None or length is None or kind.split(b";")[0].strip().lower() != b"application/json":
        return None
    token = bearer_token(auth.decode("latin-1"))
    if not length.isdigit() or int(length) > SESSION_BODY_LIMIT or token is None:
        return None
    caller = caller_for_token(scope["app"].state, token)
    if caller is None or caller.kind != "deploy" or not secrets.compare_digest(caller.id.encode(), sid.encode()):
        return None
    return caller


# --------------------------------------------------------------------------- the routes

deploy = APIRouter(prefix="/api/deploy", tags=["deploy"], responses=errors(401, 403))


@deploy.post(
    "/sessions",
    status_code=201,
    summary="Open a deploy session with a model and a policy",
    dependencies=[Depends(require_experimenter)],
    responses=errors(400),
)
def open_deploy(body: DeployIn, request: Request):
    state = request.app.state
    try:
        task, model = load_task_spec(body.task), load_model_spec(body.model)
        problems = complexity_problems(model, task) or score_problems(task)
        if problems:
            raise ConfigError(problems)
        policy = resolve_policy(body.policy, model, task, caches=state.study_caches)
        with state.db() as db:
            s = create_deploy(db, state.deploy_plans, body.label, task, model, policy, body.seed)
            db.commit()
    except TrustseekError as exc:  # a policy that does not load (non-finite values)
        raise HTTPException(400, {"problems": exc.lines()}) from None
    # this process answers the session's first requests without reading it back
    state.tokens.put(s.token, Caller(s.id, s.kind))
    state.deploy_store.remember(LiveRow(s.id, s.kind, s.seed, list(s.belief), s.trials_done, s.score))
    log.info("deploy session %s opened: %s policy", s.id, policy["kind"])
    return {
        "session_id": s.id,
        "token": s.token,
        "policy": policy["kind"],
        "belief": p_high(s.belief, model.n_trust),
        "complexities": list(task.complexities),
        "thresholds": policy.get("thresholds"),
    }


async def robot(s: Caller = Depends(require_session)) -> Caller:
    """The deploy session named in the path, if the bearer token is its token."""
    if s.kind != "deploy":
        raise HTTPException(409, "this is a participant session; use /api/sessions")
    return s


@deploy.get("/sessions/{session_id}", summary="A deploy session's state and trials", responses=errors(409))
def deploy_state(session_id: str, request: Request, s: Caller = Depends(robot)):
    with request.app.state.db() as db:
        row = db.get(Session, s.id)
        trials = db.scalars(select(Trial).where(Trial.session_id == s.id).order_by(Trial.trial)).all()
        return {
            "session_id": row.id,
            "label": row.participant,
            "trials_done": row.trials_done,
            "score": row.score,
            "belief": p_high(row.belief, len(row.plan["model"]["trust_levels"])),
            "pending": pending(row),
            "trials": [trial_dict(t) for t in trials],
        }


async def _answer(request: Request, session_id: str, what: str, args: Args) -> Response:
    """The answer of a body FastAPI validated, the token checked after it (as ``require_session``
    and ``robot`` check it)."""
    s = await robot(session_caller(request, token_of(await bearer(request)), session_id))
    status, out = await answer(request.app.state, s.id, what, args)
    return Response(out, status_code=status, media_type="application/json")


#: what decide and observe share in the API description
_ROBOT_ROUTE: dict[str, Any] = {"openapi_extra": {"security": [{"HTTPBearer": []}]}, "responses": errors(400, 404, 409)}


@deploy.post(
    "/sessions/{session_id}/decide",
    summary="Post a trial's complexity (or, for a schedule policy, the remaining items), get the robot action",
    **_ROBOT_ROUTE,
)
async def decide(session_id: str, body: DecideIn, request: Request):
    # async on purpose: a short transaction run on the event loop, without a hop to a worker thread
    return await _answer(request, session_id, "decide", (body.trial, body.complexity, body.remaining, body.visible))


@deploy.post(
    "/sessions/{session_id}/observe", summary="Post the observed human action and outcome; updates the belief", **_ROBOT_ROUTE
)
async def observe(session_id: str, body: ObserveIn, request: Request):
    return await _answer(request, session_id, "observe", (body.trial, body.human_action, body.outcome))
