"""HTTP routes of the participant: one session through its token (state, consent, quiz, trials,
self-reports, questionnaires, events)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from fastapi import APIRouter, Depends, Request
from fastapi.security import HTTPAuthorizationCredentials

from .answers import SCREENED, add_answers, add_report, answer_quiz, ended, quiz_due, still_due
from .auth import Caller, bearer, require_session, session_caller, token_of
from .errors import Conflict, Gone, NotFound
from .lifecycle import give_consent
from .orm import Session, utcnow
from .routes import errors
from .schemas import AnswersIn, ConsentIn, EventsIn, QuizAttemptIn, ReportIn, TrialIn
from .sessions import add_events, lock, participant_trial, serve, study_config, submit_trial, total_trials
from .studies import practice_count

log = logging.getLogger(__name__)

participant = APIRouter(prefix="/api/sessions", tags=["participant"], responses=errors(401, 403, 409, 410, 413))
own = APIRouter(prefix="/api", tags=["participant"], responses=errors(401, 409, 410))


# --------------------------------------------------------------------------- participant


def _not_revoked(row: Session) -> Session:
    if row.revoked_at is not None:
        raise Gone("this link has been revoked by the experimenter")
    return row


def _db(request: Request, caller: Caller, study: bool = True):
    """The caller's database: the previews' for a preview (``preview.Previews``), else the study's;
    refused for a deploy session's token unless the route takes any session (``study=False``)."""
    if study and caller.kind != "study":
        raise Conflict("this is a deploy session; use /api/deploy")
    return request.app.state.previews.db() if caller.preview else request.app.state.db()


def _locked(db, caller: Caller) -> tuple[Session, dict]:
    """The caller's session, locked for an update that depends on its state, and its study's
    configuration; refused when its link is revoked."""
    row = _not_revoked(lock(db, caller.id))
    return row, study_config(db, str(row.study_id))


def _row(db, caller: Caller) -> Session:
    """The caller's session; refused when its link is revoked."""
    row = db.get(Session, caller.id)
    if row is None:  # a preview forgotten after newer ones (preview.MAX_PREVIEWS)
        raise NotFound("this preview has expired: open a new one from the dashboard")
    return _not_revoked(row)


def session_state(request: Request, caller: Caller) -> dict:
    with _db(request, caller) as db:
        s = _row(db, caller)
        cfg = study_config(db, str(s.study_id))
        quiz = quiz_due(s, cfg)
        due, asked = still_due(db, s, cfg)
        # the next trial is served once the quiz, and the self-report and questionnaires it follows, are answered
        current = serve(db, s) if due is None and asked is None and quiz is None else None
        over = ended(db, s, cfg, (due, asked))
        if over and s.ended_at is None:
            s.ended_at = utcnow()
            db.commit()
        return {
            "session_id": s.id,
            "participant": s.participant,
            "status": s.status,
            "study": cfg["name"],
            "trials_total": total_trials(s),
            "trials_done": s.trials_done,
            "score": s.score,
            "blocks": [cfg["blocks"][b]["name"] for b in s.plan["block_order"]],
            "current": current,
            "report_due": due,
            "questionnaire": asked,
            "quiz": quiz,
            "screened": s.status == SCREENED,
            "ended": over,
            "completion": _completion(cfg, s) if over else None,
            "panel_params": cfg["panel"]["id_params"] if cfg.get("panel") else [],
            "practice_trials": practice_count(cfg),
            "self_report": cfg["self_report"],
            "animation_speed": s.speed or cfg["animation_speed"],
            "scene": cfg.get("scene", "3d"),
            "preview": s.role == "preview",
            "consent_text": cfg.get("consent_text"),
            "instructions": cfg.get("instructions"),
            "rewards": cfg["task"].get("rewards"),
        }


def _completion(cfg: dict, s: Session) -> dict | None:
    """The panel's code at the end: the completion code, or after a failed quiz that ended the
    session, the study's ``fail_code`` (none when it has none)."""
    panel = cfg.get("panel")
    code = (cfg.get("quiz") or {}).get("fail_code") if s.status == SCREENED else (panel or {}).get("completion_code")
    if not panel or not code:
        return None
    url = (panel.get("redirect_url") or "").replace("{completion_code}", code) or None
    return {"code": code, "redirect_url": url}


@own.get("/session", summary="The state of the session that the bearer token belongs to")
def own_state(request: Request, creds: HTTPAuthorizationCredentials | None = Depends(bearer)):
    return session_state(request, session_caller(request, token_of(creds)))


@participant.get("/{session_id}/state", summary="The participant's session: status, current trial, score")
def get_state(session_id: str, request: Request, s: Caller = Depends(require_session)):
    return session_state(request, s)


@participant.post("/{session_id}/consent", summary="Record consent and start the session")
def consent(session_id: str, body: ConsentIn, request: Request, s: Caller = Depends(require_session)):
    with _db(request, s) as db:
        row, cfg = _locked(db, s)
        if give_consent(db, row, cfg, body.panel):
            log.info("session %s of study %s started (consent given)", row.id, row.study_id)
            # the consent's events once: a consent posted again (a retry whose answer was lost) stores none
            add_events(db, row, [e.model_dump() for e in body.events])
    return session_state(request, s)


@participant.post("/{session_id}/trials", summary="Submit the current trial (idempotent by submission_id)", responses=errors(400))
def post_trial(session_id: str, body: TrialIn, request: Request, s: Caller = Depends(require_session)):
    with _db(request, s) as db:
        _row(db, s)
        t, dup = submit_trial(
            db, s.id, body.trial, body.submission_id, body.human_action, body.effort_ms, [e.model_dump() for e in body.events]
        )
        result = participant_trial(t)
    return {"trial": result, "duplicate": dup, "state": session_state(request, s)}


@participant.post("/{session_id}/quiz", summary="Answer the comprehension quiz (one attempt)", responses=errors(400))
def post_quiz(session_id: str, body: QuizAttemptIn, request: Request, s: Caller = Depends(require_session)):
    with _db(request, s) as db:
        wrong, dup = answer_quiz(db, *_locked(db, s), body.attempt, body.answers)
    return {"wrong": wrong, "duplicate": dup, "state": session_state(request, s)}


@participant.post("/{session_id}/reports", summary="Submit a trust self-report (0-100)")
def post_report(session_id: str, body: ReportIn, request: Request, s: Caller = Depends(require_session)):
    def add(db, row, cfg) -> tuple[dict[str, Any], bool]:
        rep, dup = add_report(db, row, cfg, body.after_trial, body.value)
        return {"after_trial": rep.after_trial, "value": rep.value, "scope": rep.scope, "duplicate": dup}, dup

    return {"report": _submitted(request, s, add), "state": session_state(request, s)}


@participant.post(
    "/{session_id}/questionnaires", summary="Answer a questionnaire (every item, on its scale)", responses=errors(400, 404)
)
def post_answers(session_id: str, body: AnswersIn, request: Request, s: Caller = Depends(require_session)):
    def add(db, row, cfg) -> tuple[dict[str, Any], bool]:
        rows, dup = add_answers(db, row, cfg, body.questionnaire, body.after_trial, body.answers)
        return {"questionnaire": body.questionnaire, "after_trial": body.after_trial, "items": len(rows), "duplicate": dup}, dup

    return {"answers": _submitted(request, s, add), "state": session_state(request, s)}


def _submitted(request: Request, s: Caller, add: Callable[..., tuple[dict[str, Any], bool]]) -> dict[str, Any]:
    """A study session's self-report or questionnaire, stored by ``add(db, row, config)`` ->
    (its answer, whether it repeats a stored one); after the session's end only a repeat (a
    retry) is taken."""
    with _db(request, s) as db:
        row = _row(db, s)
        cfg = study_config(db, str(row.study_id))
        over = ended(db, row, cfg)
        out, dup = add(db, row, cfg)
        if over and not dup:
            raise Conflict("this session has ended")
        return out


@participant.post("/{session_id}/events", summary="Log UI events")
def post_events(session_id: str, body: EventsIn, request: Request, s: Caller = Depends(require_session)):
    with _db(request, s, study=False) as db:
        row = _row(db, s)
        events = [e.model_dump() for e in body.events]
        # after the end, the outcome shown of a committed trial is still taken: the page posts
        # it as the outcome appears, and a second tab's or a slow connection's post may come
        # after another tab has ended the session
        late = all(e["type"] == "outcome_shown" and 1 <= (e["trial"] or 0) <= row.trials_done for e in events)
        if row.kind == "study" and not late and ended(db, row, study_config(db, str(row.study_id))):
            raise Conflict("this session has ended")
        n, dup = add_events(db, row, events, body.batch)
    return {"stored": n, "duplicate": dup}
