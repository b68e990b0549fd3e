"""HTTP routes: experimenter (studies, sessions, dashboard, export); the participant's are in
``participant_routes``, the decision API's in ``deploy.http``."""

from __future__ import annotations

import logging
import secrets
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError

from .auth import require_experimenter
from .export import answers_frame, bundle_files, bundle_zip, events_frame, sessions_frame, table_bytes, trials_frame
from .lifecycle import create_participant, progress
from .orm import Event, Report, Session, Study, Trial, iso, session_rows, utcnow
from .schemas import ErrorOut, SessionsIn
from .sessions import new_id, p_high, pending, study_config, total_trials, trial_dict
from .studies import ConfigError, StudyIn, build_study_config, practice_count

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


def public_url(request: Request, path: str) -> str:
    """``path`` on the server as participants reach it: under ``public_url``, else the request's base."""
    return f"{request.app.state.public_url or str(request.base_url).rstrip('/')}{path}"


def session_link(request: Request, s: Session) -> str:
    """The participant's link of session ``s``."""
    return public_url(request, f"/s/{s.token}")


def attachment(content: bytes, media_type: str, name: str) -> Response:
    """A file to download, named ``name``."""
    return Response(content, media_type=media_type, headers={"Content-Disposition": f'attachment; filename="{name}"'})


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
        cfg = build_study_config(body, request.app.state.study_caches)
    except ConfigError as exc:
        raise HTTPException(400, {"problems": exc.problems}) from None
    with request.app.state.db() as db:
        st = Study(id=new_id(), name=body.name, config=cfg, status=status, link_token=secrets.token_urlsafe(24))
        db.add(st)
        db.commit()
        log.info("study %s created: %r, %d blocks", st.id, st.name, len(cfg["blocks"]))
        return study_summary(db, st, request)


def study_summary(db, st: Study, request: Request) -> dict:
    counts = progress(db, st.id)
    cfg = st.config
    return {
        "id": st.id,
        "name": st.name,
        "created_at": iso(st.created_at),
        "status": st.status,
        "link": public_url(request, f"/join/{st.link_token}") if st.link_token else None,
        "quota": cfg.get("quota"),
        "participants": sum(v for k, v in counts.items() if k != "pilot"),
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
    with request.app.state.db() as db:
        return [study_summary(db, st, request) for st in db.scalars(select(Study).order_by(Study.created_at))]


def study_or_404(db, study_id: str) -> Study:
    """The study ``study_id``, or a 404 answer."""
    st = db.get(Study, study_id)
    if st is None:
        raise HTTPException(404, f"no study {study_id!r}")
    return st


@experimenter.get("/studies/{study_id}", summary="A study's configuration", responses=errors(404))
def get_study(study_id: str, request: Request):
    with request.app.state.db() as db:
        st = study_or_404(db, study_id)
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
    with request.app.state.db() as db:
        st = study_or_404(db, study_id)
        if st.status == "closed":
            raise HTTPException(409, f"study {study_id} is closed: it takes no new participants")
        role = "pilot" if body.pilot or st.status == "draft" else "participant"
        try:  # each session is flushed before the next is made (the database session autoflushes)
            made = [create_participant(db, st, label, role=role) for label in labels]
            db.commit()
        except IntegrityError:
            db.rollback()
            raise HTTPException(409, "a participant id was taken concurrently; retry") from None
        out = [
            {
                "participant": s.participant,
                "session_id": s.id,
                "role": s.role,
                "token": s.token,
                "link": session_link(request, s),
                "block_order": [st.config["blocks"][b]["name"] for b in s.plan["block_order"]],
                "trials": total_trials(s),
            }
            for s in made
        ]
    log.info("study %s: %d participant sessions created", study_id, len(out))
    return out


@experimenter.get("/studies/{study_id}/dashboard", summary="Live state of every participant", responses=errors(404))
def dashboard(study_id: str, request: Request):
    with request.app.state.db() as db:
        st = study_or_404(db, study_id)
        sessions = db.scalars(
            select(Session)
            .where(Session.study_id == st.id, Session.role != "preview")
            .order_by(Session.created_at, Session.participant)
        ).all()
        in_study = [Session.study_id == st.id]
        latest = session_rows(Event, in_study, Event.session_id, func.max(Event.created_at)).group_by(Event.session_id)
        seen = dict(db.execute(latest).all())
        last_trials = db.scalars(session_rows(Trial, in_study).where(Trial.trial == Session.trials_done))
        last = {t.session_id: {**trial_dict(t), "practice": bool(t.practice)} for t in last_trials}
        reports = {r.session_id: r.value for r in db.scalars(session_rows(Report, in_study).order_by(Report.after_trial))}
        cfg = study_config(db, st.id)
        n_trust, practice = len(cfg["model"]["trust_levels"]), practice_count(cfg)
        rows = [
            {
                "participant": s.participant,
                "session_id": s.id,
                "status": s.status,
                "link": session_link(request, s),
                "trials_done": s.trials_done,
                "trials_total": total_trials(s),
                "practice_trials": practice,
                "score": s.score,
                "belief": p_high(s.belief, n_trust),
                "current": pending(s),
                "last": last.get(s.id),
                "last_self_report": reports.get(s.id),
                "updated_at": iso(s.updated_at),
                "role": s.role,
                "panel_id": s.panel_id or next(iter((s.panel or {}).values()), None),
                "created_at": iso(s.created_at),
                "started_at": iso(s.consented_at),
                "ended_at": iso(s.ended_at),
                "last_activity": iso(max(t for t in (s.updated_at, seen.get(s.id)) if t is not None)),
                "revoked": s.revoked_at is not None,
            }
            for s in sessions
        ]
        return {"study": study_summary(db, st, request), "participants": rows, "time": iso(utcnow())}


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
    with request.app.state.db() as db:
        st = study_or_404(db, study_id)
        if table == "trials":
            frame = trials_frame(db, st, practice=practice, pilot=pilot)
        else:
            frame = {"events": events_frame, "reports": answers_frame, "sessions": sessions_frame}[table](db, st, pilot)
    # text from participants' browsers: formulas escaped, CR/LF quoted
    content = table_bytes(frame, format, escaped=table != "trials")
    media = "text/csv" if format == "csv" else "application/vnd.apache.parquet"
    return attachment(content, media, f"{st.id}-{table}.{format}")


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
    with request.app.state.db() as db:
        st = study_or_404(db, study_id)
        content = bundle_zip(bundle_files(db, st, pilot), f"{st.id}-bundle")
    return attachment(content, "application/zip", f"{st.id}-bundle.zip")
