"""HTTP routes: experimenter (studies, sessions, dashboard, export), participant (one session
through its token) and deploy (decisions for a real robot)."""

from __future__ import annotations

import json
import logging
import secrets
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from fastapi.security import HTTPAuthorizationCredentials
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError

from .auth import Caller, bearer, remember_token, require_experimenter, require_session, session_for_token, token_of
from .deploy import committed_trial, create_deploy, deploy_decide, deploy_observe, remember_deploy
from .export import answers_frame, events_csv, events_frame, sessions_frame, to_bytes, trials_frame
from .orm import Report, Session, Study, Trial, utcnow
from .schemas import AnswersIn, ConsentIn, DecideIn, DeployIn, ErrorOut, EventsIn, ObserveIn, ReportIn, SessionsIn, TrialIn
from .sessions import (
    SessionError,
    add_answers,
    add_events,
    add_report,
    create_participant,
    ended,
    lock,
    new_id,
    p_high,
    participant_trial,
    questionnaire_due,
    report_due,
    serve,
    study_config,
    submit_trial,
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
    413: "The body is too large, or the session already holds as many events as it may.",
}


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` for the refusals a route can answer (FastAPI declares 422 itself)."""
    return {code: {"model": ErrorOut, "description": _WHY[code]} for code in codes}


experimenter = APIRouter(
    prefix="/api", tags=["experimenter"], dependencies=[Depends(require_experimenter)], responses=errors(401, 403)
)
participant = APIRouter(prefix="/api/sessions", tags=["participant"], responses=errors(401, 403, 409, 413))
deploy = APIRouter(prefix="/api/deploy", tags=["deploy"], responses=errors(401, 403))
own = APIRouter(prefix="/api", tags=["participant"], responses=errors(401, 409))


def _db(request: Request):
    return request.app.state.db()


def _fail(exc: SessionError):
    raise HTTPException(exc.status, exc.message)


def _link(request: Request, s: Session) -> str:
    return f"{request.app.state.public_url or str(request.base_url).rstrip('/')}/s/{s.token}"


# --------------------------------------------------------------------------- experimenter


@experimenter.post("/studies", status_code=201, summary="Create a study", responses=errors(400))
def create_study(body: StudyIn, request: Request):
    try:
        cfg = build_study_config(body)
    except ConfigError as exc:
        raise HTTPException(400, {"problems": exc.problems}) from None
    with _db(request) as db:
        st = Study(id=new_id(), name=body.name, config=cfg)
        db.add(st)
        db.commit()
        log.info("study %s created: %r, %d blocks", st.id, st.name, len(cfg["blocks"]))
        return study_summary(db, st)


def study_summary(db, st: Study) -> dict:
    n = len(db.scalars(select(Session.id).where(Session.study_id == st.id)).all())
    cfg = st.config
    return {
        "id": st.id,
        "name": st.name,
        "created_at": st.created_at.isoformat() + "Z",
        "participants": n,
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
        return [study_summary(db, st) for st in db.scalars(select(Study).order_by(Study.created_at))]


def _study(db, study_id: str) -> Study:
    st = db.get(Study, study_id)
    if st is None:
        raise HTTPException(404, f"no study {study_id!r}")
    return st


@experimenter.get("/studies/{study_id}", summary="A study's configuration", responses=errors(404))
def get_study(study_id: str, request: Request):
    with _db(request) as db:
        st = _study(db, study_id)
        return {**study_summary(db, st), "config": st.config}


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
        try:
            for label in labels:
                s = create_participant(db, st, label)
                db.flush()
                out.append(
                    {
                        "participant": s.participant,
                        "session_id": s.id,
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
            select(Session).where(Session.study_id == st.id).order_by(Session.created_at, Session.participant)
        ).all()
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
                }
            )
        return {"study": study_summary(db, st), "participants": rows, "time": utcnow().isoformat() + "Z"}


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
):
    with _db(request) as db:
        st = _study(db, study_id)
        if table == "trials":
            frame = trials_frame(db, st, practice=practice)
        else:
            frame = {"events": events_frame, "reports": answers_frame, "sessions": sessions_frame}[table](db, st)
    # text from participants' browsers: formulas escaped, CR/LF quoted
    content = events_csv(frame) if table != "trials" and format == "csv" else to_bytes(frame, format)
    media = "text/csv" if format == "csv" else "application/vnd.apache.parquet"
    name = f"{st.id}-{table}.{format}"
    return Response(content, media_type=media, headers={"Content-Disposition": f'attachment; filename="{name}"'})


# --------------------------------------------------------------------------- participant


def _study_session(s: Caller) -> None:
    if s.kind != "study":
        raise HTTPException(409, "this is a deploy session; use /api/deploy")


def session_state(request: Request, s_id: str) -> dict:
    with _db(request) as db:
        s = db.get(Session, s_id)
        if s.kind != "study":
            raise HTTPException(409, "this is a deploy session; use /api/deploy")
        cfg = study_config(db, s.study_id)
        due = report_due(db, s, cfg)
        asked = questionnaire_due(db, s, cfg) if due is None else None
        # the next trial is served once the self-report and questionnaires it follows are answered
        current = serve(db, s) if due is None and asked is None else None
        blocks = s.plan["block_order"]
        panel = cfg.get("panel")
        over = s.status == "done" and due is None and asked is None
        completion = None
        if over and panel:
            code = panel["completion_code"]
            url = (panel.get("redirect_url") or "").replace("{completion_code}", code) or None
            completion = {"code": code, "redirect_url": url}
        return {
            "session_id": s.id,
            "participant": s.participant,
            "status": s.status,
            "study": cfg["name"],
            "trials_total": total_trials(s),
            "trials_done": s.trials_done,
            "score": s.score,
            "blocks": [cfg["blocks"][b]["name"] for b in blocks],
            "current": current,
            "report_due": due,
            "questionnaire": asked,
            "ended": over,
            "completion": completion,
            "panel_params": panel["id_params"] if panel else [],
            "practice_trials": len(cfg["practice"]["trials"]) if cfg.get("practice") else 0,
            "self_report": cfg["self_report"],
            "animation_speed": cfg["animation_speed"],
            "scene": cfg.get("scene", "3d"),
            "consent_text": cfg.get("consent_text"),
            "instructions": cfg.get("instructions"),
            "rewards": cfg["task"].get("rewards"),
        }


@own.get("/session", summary="The state of the session that the bearer token belongs to")
def own_state(request: Request, creds: HTTPAuthorizationCredentials | None = Depends(bearer)):
    s = session_for_token(request, token_of(creds))
    if s.kind != "study":
        raise HTTPException(409, "this is a deploy session; use /api/deploy")
    return session_state(request, s.id)


@participant.get("/{session_id}/state", summary="The participant's session: status, current trial, score")
def get_state(session_id: str, request: Request, s: Caller = Depends(require_session)):
    _study_session(s)
    return session_state(request, s.id)


@participant.post("/{session_id}/consent", summary="Record consent and start the session")
def consent(session_id: str, body: ConsentIn, request: Request, s: Caller = Depends(require_session)):
    _study_session(s)
    with _db(request) as db:
        row = lock(db, s.id)
        cfg = study_config(db, str(row.study_id))
        started = row.status == "new"
        if started:
            wanted = (cfg.get("panel") or {}).get("id_params", [])
            ids = {k: v for k, v in body.panel.items() if k in wanted}
            row.status, row.consented_at, row.updated_at = "running", utcnow(), utcnow()
            row.panel = ids or None
        elif ended(db, row, cfg):
            db.rollback()
            raise HTTPException(409, "this session has ended")
        db.commit()
        if started:
            log.info("session %s of study %s started (consent given)", row.id, row.study_id)
        if body.events:
            try:
                add_events(db, row, [e.model_dump() for e in body.events])
            except SessionError as exc:
                db.rollback()
                _fail(exc)
    return session_state(request, s.id)


@participant.post("/{session_id}/trials", summary="Submit the current trial (idempotent by submission_id)", responses=errors(400))
def post_trial(session_id: str, body: TrialIn, request: Request, s: Caller = Depends(require_session)):
    _study_session(s)
    with _db(request) as db:
        try:
            t, dup = submit_trial(
                db, s.id, body.trial, body.submission_id, body.human_action, body.effort_ms, [e.model_dump() for e in body.events]
            )
        except SessionError as exc:
            db.rollback()
            _fail(exc)
        result = participant_trial(t)
    return {"trial": result, "duplicate": dup, "state": session_state(request, s.id)}


@participant.post("/{session_id}/reports", summary="Submit a trust self-report (0-100)")
def post_report(session_id: str, body: ReportIn, request: Request, s: Caller = Depends(require_session)):
    _study_session(s)
    with _db(request) as db:
        row = db.get(Session, s.id)
        cfg = study_config(db, row.study_id) if row.study_id else {}
        try:
            if ended(db, row, cfg):
                raise SessionError(409, "this session has ended")
            rep, dup = add_report(db, row, cfg, body.after_trial, body.value)
        except SessionError as exc:
            db.rollback()
            _fail(exc)
        out = {"after_trial": rep.after_trial, "value": rep.value, "scope": rep.scope, "duplicate": dup}
    return {"report": out, "state": session_state(request, s.id)}


@participant.post(
    "/{session_id}/questionnaires", summary="Answer a questionnaire (every item, on its scale)", responses=errors(400, 404)
)
def post_answers(session_id: str, body: AnswersIn, request: Request, s: Caller = Depends(require_session)):
    _study_session(s)
    with _db(request) as db:
        row = db.get(Session, s.id)
        cfg = study_config(db, row.study_id)
        try:
            if ended(db, row, cfg):
                raise SessionError(409, "this session has ended")
            rows, dup = add_answers(db, row, cfg, body.questionnaire, body.after_trial, body.answers)
        except SessionError as exc:
            db.rollback()
            _fail(exc)
        out = {"questionnaire": body.questionnaire, "after_trial": body.after_trial, "items": len(rows), "duplicate": dup}
    return {"answers": out, "state": session_state(request, s.id)}


@participant.post("/{session_id}/events", summary="Log UI events")
def post_events(session_id: str, body: EventsIn, request: Request, s: Caller = Depends(require_session)):
    with _db(request) as db:
        row = db.get(Session, s.id)
        try:
            if row.kind == "study" and ended(db, row, study_config(db, row.study_id)):
                raise SessionError(409, "this session has ended")
            n, dup = add_events(db, row, [e.model_dump() for e in body.events], body.batch)
        except SessionError as exc:
            db.rollback()
            _fail(exc)
    return {"stored": n, "duplicate": dup}


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
