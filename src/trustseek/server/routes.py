"""HTTP routes: experimenter (studies, sessions, dashboard, export) and deploy (decisions for a
real robot); the participant's are in ``participant_routes``."""

from __future__ import annotations

import json
import logging
import secrets
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError

from .auth import Caller, remember_token, require_experimenter, require_session, session_for_token
from .bundle import bundle_files, bundle_zip
from .deploy import committed_trial, create_deploy, deploy_decide, deploy_observe, remember_deploy
from .export import answers_frame, events_csv, events_frame, sessions_frame, to_bytes, trials_frame
from .lifecycle import create_participant, progress
from .orm import Event, Report, Session, Study, Trial, utcnow
from .schemas import (
    DecideIn,
    DeployIn,
    ErrorOut,
    ObserveIn,
    SessionsIn,
)
from .sessions import (
    SessionError,
    new_id,
    p_high,
    study_config,
    total_trials,
    trial_dict,
)
from .store import LiveRow
from .studies import ConfigError, StudyIn, build_study_config, load_model_spec, load_task_spec, resolve_policy

log = logging.getLogger(__name__)

_WHY = {
    400: "The request is well-formed but not allowed (an invalid configuration, an action the trial does not allow).",
    401: "No token, or an unknown token.",
    403: "The token is not the experimenter's, or belongs to another session.",
    404: "No such study or session.",
    409: "The session's state does not allow it (not the current trial, a conflicting repeat, the wrong kind of session, "
    "a session that has ended).",
    410: "The experimenter has revoked this session's link.",
    413: "The body is too large, or the session already holds as many events as it may.",
}


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` for the refusals a route can answer (FastAPI declares 422 itself)."""
    return {code: {"model": ErrorOut, "description": _WHY[code]} for code in codes}


experimenter = APIRouter(
    prefix="/api", tags=["experimenter"], dependencies=[Depends(require_experimenter)], responses=errors(401, 403)
)
deploy = APIRouter(prefix="/api/deploy", tags=["deploy"], responses=errors(401, 403))


def _db(request: Request):
    return request.app.state.db()


def _fail(exc: SessionError):
    raise HTTPException(exc.status, exc.message)


def _link(request: Request, s: Session) -> str:
    return f"{request.app.state.public_url or str(request.base_url).rstrip('/')}/s/{s.token}"


# --------------------------------------------------------------------------- experimenter


@experimenter.post(
    "/studies",
    status_code=201,
    summary="Create a study",
    description="Open at once, or a draft with ``status=draft`` (links made in a draft are pilots; the study link "
    "takes no one until the study is opened).",
    responses=errors(400),
)
def create_study(body: StudyIn, request: Request, status: str = Query("open", pattern="^(draft|open)$")):
    try:
        cfg = build_study_config(body)
    except ConfigError as exc:
        raise HTTPException(400, {"problems": exc.problems}) from None
    with _db(request) as db:
        st = Study(id=new_id(), name=body.name, config=cfg, status=status, link_token=secrets.token_urlsafe(24))
        db.add(st)
        db.commit()
        log.info("study %s created: %r, %d blocks", st.id, st.name, len(cfg["blocks"]))
        return study_summary(db, st, request)


def study_summary(db, st: Study, request: Request) -> dict:
    counts = progress(db, st.id)
    cfg = st.config
    base = request.app.state.public_url or str(request.base_url).rstrip("/")
    return {
        "id": st.id,
        "name": st.name,
        "created_at": st.created_at.isoformat() + "Z",
        "status": st.status,
        "link": f"{base}/join/{st.link_token}" if st.link_token else None,
        "quota": cfg.get("quota"),
        "participants": sum(v for k, v in counts.items() if k not in ("pilot", "preview")),
        "progress": counts,
        "blocks": [
            {
                "name": b["name"],
                "policy": b["policy"]["kind"],
                "thresholds": b["policy"].get("thresholds"),
                "schedule": b["schedule"],
            }
            for b in cfg["blocks"]
        ],
        "counterbalance": cfg["counterbalance"],
        "self_report": cfg["self_report"],
        "animation_speed": cfg["animation_speed"],
    }


@experimenter.get("/studies", summary="List studies")
def list_studies(request: Request):
    with _db(request) as db:
        return [study_summary(db, st, request) for st in db.scalars(select(Study).order_by(Study.created_at))]


def _study(db, study_id: str) -> Study:
    st = db.get(Study, study_id)
    if st is None:
        raise HTTPException(404, f"no study {study_id!r}")
    return st


@experimenter.get("/studies/{study_id}", summary="A study's configuration", responses=errors(404))
def get_study(study_id: str, request: Request):
    with _db(request) as db:
        st = _study(db, study_id)
        return {**study_summary(db, st, request), "config": st.config}


@experimenter.post(
    "/studies/{study_id}/sessions",
    status_code=201,
    summary="Create participant sessions, one link each",
    responses=errors(400, 404, 409),
)
def create_sessions(study_id: str, body: SessionsIn, request: Request):
    labels = body.participants if body.participants is not None else [None] * body.count
    if body.participants is not None:
        bad = [p for p in body.participants if not p or len(p) > 200]
        if bad or len(set(body.participants)) != len(body.participants):
            raise HTTPException(400, "participant ids must be unique, non-empty strings of at most 200 characters")
    out = []
    with _db(request) as db:
        st = _study(db, study_id)
        if st.status == "closed":
            raise HTTPException(409, f"study {study_id} is closed: it takes no new participants")
        role = "pilot" if body.pilot or st.status == "draft" else "participant"
        try:
            for label in labels:
                s = create_participant(db, st, label, role=role)
                db.flush()
                out.append(
                    {
                        "participant": s.participant,
                        "session_id": s.id,
                        "role": s.role,
                        "token": s.token,
                        "link": _link(request, s),
                        "block_order": [st.config["blocks"][b]["name"] for b in s.plan["block_order"]],
                        "trials": total_trials(s),
                    }
                )
        except SessionError as exc:
            db.rollback()
            _fail(exc)
        except IntegrityError:
            db.rollback()
            raise HTTPException(409, "a participant id was taken concurrently; retry") from None
        try:
            db.commit()
        except IntegrityError:
            db.rollback()
            raise HTTPException(409, "a participant id was taken concurrently; retry") from None
    log.info("study %s: %d participant sessions created", study_id, len(out))
    return out


@experimenter.get("/studies/{study_id}/dashboard", summary="Live state of every participant", responses=errors(404))
def dashboard(study_id: str, request: Request):
    with _db(request) as db:
        st = _study(db, study_id)
        sessions = db.scalars(
            select(Session)
            .where(Session.study_id == st.id, Session.role != "preview")
            .order_by(Session.created_at, Session.participant)
        ).all()
        seen = dict(
            db.execute(
                select(Event.session_id, func.max(Event.created_at))
                .join(Session, Event.session_id == Session.id)
                .where(Session.study_id == st.id)
                .group_by(Event.session_id)
            ).all()
        )
        last = {}
        for t in db.scalars(
            select(Trial)
            .join(Session, Trial.session_id == Session.id)
            .where(Session.study_id == st.id, Trial.trial == Session.trials_done)
        ):
            last[t.session_id] = trial_dict(t)
        reports = {}
        for r in db.scalars(
            select(Report)
            .join(Session, Report.session_id == Session.id)
            .where(Session.study_id == st.id)
            .order_by(Report.after_trial)
        ):
            reports[r.session_id] = r.value
        rows = []
        n_trust = len(study_config(db, st.id)["model"]["trust_levels"])
        for s in sessions:
            rows.append(
                {
                    "participant": s.participant,
                    "session_id": s.id,
                    "status": s.status,
                    "link": _link(request, s),
                    "trials_done": s.trials_done,
                    "trials_total": total_trials(s),
                    "score": s.score,
                    "belief": p_high(s.belief, n_trust),
                    "current": None
                    if s.pending_trial is None
                    else {"trial": s.pending_trial, "complexity": s.pending_complexity, "robot_action": s.pending_action},
                    "last": last.get(s.id),
                    "last_self_report": reports.get(s.id),
                    "updated_at": s.updated_at.isoformat() + "Z",
                    "role": s.role,
                    "panel_id": s.panel_id or _first_panel_id(s.panel),
                    "created_at": _iso(s.created_at),
                    "started_at": _iso(s.consented_at),
                    "ended_at": _iso(s.ended_at),
                    "last_activity": _iso(max(t for t in (s.updated_at, seen.get(s.id)) if t is not None)),
                    "revoked": s.revoked_at is not None,
                }
            )
        return {"study": study_summary(db, st, request), "participants": rows, "time": utcnow().isoformat() + "Z"}


def _iso(t) -> str | None:
    return None if t is None else t.isoformat() + "Z"


def _first_panel_id(panel: dict | None) -> str | None:
    return next(iter(panel.values()), None) if panel else None


@experimenter.get(
    "/studies/{study_id}/export",
    summary="Export trials (canonical trial log), self-reports, sessions or UI events",
    description="CSV or Parquet.  ``trials``: the analysis trial log (what ``trustseek fit`` reads), without "
    "practice trials unless ``practice=true``; ``reports``: every self-report and questionnaire item, one row "
    "each (long format), next to the trial it follows; ``sessions``: one row per participant with the panel ids "
    "and the seed and secret that reproduce the session.  In the CSV of the events, reports and sessions tables, "
    "text cells that a spreadsheet would read as a formula (starting with = + - @, a tab or a carriage return) "
    "are prefixed with ' (literal text), and lines end with CRLF (RFC 4180).",
    response_class=Response,
    responses={
        200: {
            "description": "The table as a file (an attachment).",
            "content": {
                "text/csv": {"schema": {"type": "string"}},
                "application/vnd.apache.parquet": {"schema": {"type": "string", "format": "binary"}},
            },
        },
        **errors(404),
    },
)
def export(
    study_id: str,
    request: Request,
    table: str = Query("trials", pattern="^(trials|events|reports|sessions)$"),
    format: str = Query("csv", pattern="^(csv|parquet)$"),
    practice: bool = Query(False, description="Trials: include the practice trials (the full log)."),
    pilot: bool = Query(False, description="Include the pilot sessions (left out of the analysis export by default)."),
):
    with _db(request) as db:
        st = _study(db, study_id)
        if table == "trials":
            frame = trials_frame(db, st, practice=practice, pilot=pilot)
        else:
            frame = {"events": events_frame, "reports": answers_frame, "sessions": sessions_frame}[table](db, st, pilot)
    # text from participants' browsers: formulas escaped, CR/LF quoted
    content = events_csv(frame) if table != "trials" and format == "csv" else to_bytes(frame, format)
    media = "text/csv" if format == "csv" else "application/vnd.apache.parquet"
    name = f"{st.id}-{table}.{format}"
    return Response(content, media_type=media, headers={"Content-Disposition": f'attachment; filename="{name}"'})


@experimenter.get(
    "/studies/{study_id}/bundle",
    summary="Every table of a study in CSV and Parquet, its configuration and a data dictionary (a zip file)",
    response_class=Response,
    responses={
        200: {
            "description": "The bundle (a zip file).",
            "content": {"application/zip": {"schema": {"type": "string", "format": "binary"}}},
        },
        **errors(404),
    },
)
def bundle(study_id: str, request: Request, pilot: bool = Query(False, description="Include the pilot sessions.")):
    with _db(request) as db:
        st = _study(db, study_id)
        content = bundle_zip(bundle_files(db, st, pilot), f"{st.id}-bundle")
    name = f"{st.id}-bundle.zip"
    return Response(content, media_type="application/zip", headers={"Content-Disposition": f'attachment; filename="{name}"'})


# --------------------------------------------------------------------------- deploy


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
        if tuple(model.complexities) != tuple(task.complexities):
            raise ConfigError(
                [f"the model's complexities {list(model.complexities)} differ from the task's {list(task.complexities)}"]
            )
        policy = resolve_policy(body.policy, model, task)
    except ConfigError as exc:
        raise HTTPException(400, {"problems": exc.problems}) from None
    with _db(request) as db:
        s = create_deploy(db, body.label, task, model, policy, body.seed)
        db.commit()
        # this process answers the session's first requests without reading it back
        remember_token(request.app.state, s.token, Caller(s.id, s.kind))
        remember_deploy(s, task, model)
        request.app.state.deploy_store.remember(
            LiveRow(s.id, s.kind, s.seed, list(s.belief), s.trials_done, s.score, None, None, None)
        )
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
    with _db(request) as db:
        row = db.get(Session, s.id)
        trials = db.scalars(select(Trial).where(Trial.session_id == s.id).order_by(Trial.trial)).all()
        return {
            "session_id": row.id,
            "label": row.participant,
            "trials_done": row.trials_done,
            "score": row.score,
            "belief": p_high(row.belief, len(row.plan["model"]["trust_levels"])),
            "pending": None
            if row.pending_trial is None
            else {"trial": row.pending_trial, "complexity": row.pending_complexity, "robot_action": row.pending_action},
            "trials": [trial_dict(t) for t in trials],
        }


def _robot(request: Request, session_id: str) -> Caller:
    """The deploy session named in the path, if the bearer token is its token (the check of
    ``require_session``, made inline: the decision API is latency-critical)."""
    header = request.headers.get("authorization", "")
    scheme, _, token = header.partition(" ")
    if scheme.lower() != "bearer" or not token:
        raise HTTPException(401, "missing token: send 'Authorization: Bearer <token>'", headers={"WWW-Authenticate": "Bearer"})
    s = session_for_token(request, token.strip())
    if not secrets.compare_digest(s.id.encode(), session_id.encode()):
        raise HTTPException(403, "this token belongs to another session")
    _deploy_session(s)
    return s


_BEARER: dict[str, Any] = {"security": [{"HTTPBearer": []}]}


def _json(out: dict) -> Response:
    """A JSON response of plain values (str, int, float, None), serialized directly."""
    return Response(json.dumps(out, allow_nan=False, separators=(",", ":")).encode(), media_type="application/json")


@deploy.post(
    "/sessions/{session_id}/decide",
    summary="Post a trial's complexity (or, for a schedule policy, the remaining items), get the robot action",
    openapi_extra=_BEARER,
    responses=errors(400, 404, 409),
)
async def decide(session_id: str, body: DecideIn, request: Request):
    # async on purpose: a short transaction run on the event loop, without a hop to a worker thread
    s = _robot(request, session_id)
    try:
        with request.app.state.deploy_store.transaction() as tx:
            out = deploy_decide(tx, s.id, body.trial, body.complexity, body.remaining, body.visible)
    except SessionError as exc:
        _fail(exc)
    return _json(out)


@deploy.post(
    "/sessions/{session_id}/observe",
    summary="Post the observed human action and outcome; updates the belief",
    openapi_extra=_BEARER,
    responses=errors(400, 404, 409),
)
async def observe(session_id: str, body: ObserveIn, request: Request):
    s = _robot(request, session_id)
    store = request.app.state.deploy_store
    try:
        with store.transaction() as tx:
            t, dup = deploy_observe(tx, s.id, body.trial, body.human_action, body.outcome)
    except SessionError as exc:
        _fail(exc)
    except store.IntegrityError:  # committed by a concurrent request in the meantime
        with store.transaction() as tx:
            old = committed_trial(tx, s.id, body.trial)
        if old is None:
            raise
        t, dup = trial_dict(old), True
    return _json({"trial": t, "duplicate": dup, "belief": t["belief_after"]})
