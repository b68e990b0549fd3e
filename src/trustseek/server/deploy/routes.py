"""The decision API's FastAPI routes: opening a deploy session, its state, and ``decide`` and
``observe`` for the bodies that reach FastAPI (``http.DeployFront`` answers the others with the
same ``http.answer``).  HTTP status codes are given here and in ``middleware.STATUS``, nowhere else."""

from __future__ import annotations

import logging
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Request, Response
from sqlalchemy import select

from ...errors import TrustseekError
from ..auth import Caller, bearer_token, missing_token, remember_token, require_experimenter, require_session, session_caller
from ..orm import Session, Trial
from ..routes import errors
from ..schemas import DecideIn, DeployIn, ObserveIn
from ..sessions import p_high, pending, trial_dict
from ..studies import ConfigError, complexity_problems, load_model_spec, load_task_spec, resolve_policy
from .http import answer
from .service import create_deploy, score_problem
from .store import LiveRow

log = logging.getLogger(__name__)

deploy = APIRouter(prefix="/api/deploy", tags=["deploy"], responses=errors(401, 403))
_BEARER: dict[str, Any] = {"security": [{"HTTPBearer": []}]}


@deploy.post(
    "/sessions",
    status_code=201,
    summary="Open a deploy session with a model and a policy",
    dependencies=[Depends(require_experimenter)],
    responses=errors(400),
)
def open_deploy(body: DeployIn, request: Request):
    try:
        task, model = load_task_spec(body.task), load_model_spec(body.model)
        problems = complexity_problems(model, task) or [p for p in [score_problem(task)] if p is not None]
        if problems:
            raise ConfigError(problems)
        policy = resolve_policy(body.policy, model, task, caches=request.app.state.study_caches)
    except ConfigError as exc:
        raise HTTPException(400, {"problems": exc.problems}) from None
    state = request.app.state
    with state.db() as db:
        try:
            s = create_deploy(db, state.deploy_plans, body.label, task, model, policy, body.seed)
        except TrustseekError as exc:  # a policy that does not load (non-finite values)
            raise HTTPException(400, {"problems": exc.lines()}) from None
        db.commit()
        # this process answers the session's first requests without reading it back
        remember_token(state, s.token, Caller(s.id, s.kind))
        state.deploy_store.remember(LiveRow(s.id, s.kind, s.seed, list(s.belief), s.trials_done, s.score, None, None, None))
        log.info("deploy session %s opened: %s policy", s.id, policy["kind"])
        return {
            "session_id": s.id,
            "token": s.token,
            "policy": policy["kind"],
            "belief": p_high(s.belief, model.n_trust),
            "complexities": list(task.complexities),
            "thresholds": policy.get("thresholds"),
        }


def _deploy_session(s: Caller) -> None:
    if s.kind != "deploy":
        raise HTTPException(409, "this is a participant session; use /api/sessions")


@deploy.get("/sessions/{session_id}", summary="A deploy session's state and trials", responses=errors(409))
def deploy_state(session_id: str, request: Request, s: Caller = Depends(require_session)):
    _deploy_session(s)
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


def _robot(request: Request, session_id: str) -> Caller:
    """The deploy session named in the path, if the bearer token is its token (the check of
    ``require_session``, made inline)."""
    token = bearer_token(request.headers.get("authorization", ""))
    if token is None:
        raise missing_token()
    s = session_caller(request, token, session_id)
    _deploy_session(s)
    return s


#: what decide and observe share in the API description
_ROBOT_ROUTE: dict[str, Any] = {"openapi_extra": _BEARER, "responses": errors(400, 404, 409)}


async def _answer(request: Request, session_id: str, what: str, args: tuple) -> Response:
    """The deploy session's answer to ``decide`` or ``observe`` (:func:`http.answer`)."""
    s = _robot(request, session_id)
    status, out = await answer(request.app.state, s.id, what, args)
    return Response(out, status_code=status, media_type="application/json")


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
