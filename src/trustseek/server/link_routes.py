"""The study link and the study's lifecycle over HTTP: ``/join/<link token>`` (one URL for an
online panel), the participant's page ``/s/<token>`` (or a page saying why not: a revoked link,
a paused or closed study), and the experimenter's lifecycle, preview and revocation routes."""

from __future__ import annotations

import html
import logging
import urllib.parse
from pathlib import Path

from fastapi import APIRouter, Depends, HTTPException, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
from sqlalchemy import select

from .auth import require_experimenter
from .lifecycle import Arrival, arrive, panel_ids, refusal, revoke, set_status
from .orm import Session, Study, iso
from .routes import errors, public_url, session_link, study_or_404
from .schemas import StatusIn
from .sessions import study_config

log = logging.getLogger(__name__)

STATIC = Path(__file__).resolve().parent.parent / "static" / "app"
#: the headers of every page: never cached, and the link (with its token) never sent on
PAGE_HEADERS = {"Cache-Control": "no-store", "Referrer-Policy": "no-referrer"}

#: (HTTP status, title, text) of each page shown instead of the study
PAGES = {
    "completed": (
        200,
        "You have already completed this study",
        "Thank you: your session is complete, and each person takes part once. You may close this page.",
    ),
    "paused": (
        409,
        "The study is paused",
        "The study is not taking new participants at the moment. Please try again later; nothing has been recorded.",
    ),
    "closed": (409, "The study is closed", "The study is no longer taking participants. Nothing has been recorded."),
    "full": (409, "The study is full", "Every place in this study has been taken. Nothing has been recorded."),
    "draft": (409, "The study has not started", "The study is not open yet. Please try again later."),
    "no-id": (
        400,
        "Your panel id is missing",
        "This link needs your participant id from the panel (e.g. PROLIFIC_PID=... in the address). "
        "Please open the study from the panel's page.",
    ),
    "revoked": (410, "This link has been revoked", "The experimenter has withdrawn this link. Nothing more is recorded."),
    "invalid": (
        404,
        "This link is not valid",
        "Please check the address you were given, or ask the experimenter for a new link.",
    ),
}


def message_page(kind: str) -> HTMLResponse:
    """A small page in the participant interface's style saying why the study is not shown."""
    status, title, text = PAGES[kind]
    body = (
        '<!doctype html><html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1"><meta name="referrer" content="no-referrer">'
        f'<title>{html.escape(title)}</title><link rel="icon" href="data:,"><link rel="stylesheet" href="/static/app/style.css">'
        f'</head><body data-page="{kind}"><main id="app"><section class="screen card"><h1>{html.escape(title)}</h1>'
        f"<p>{html.escape(text)}</p></section></main></body></html>"
    )
    return HTMLResponse(body, status_code=status, headers=PAGE_HEADERS)


def static_page(name: str) -> FileResponse:
    path = STATIC / name
    if not path.exists():
        raise HTTPException(503, "the web front end is not built: run scripts/setup.sh (npm ci && npm run build in web/)")
    return FileResponse(path, media_type="text/html", headers=PAGE_HEADERS)


pages = APIRouter(include_in_schema=False)


@pages.get("/s/{token}")
def participant_page(token: str, request: Request) -> Response:
    with request.app.state.db() as db:
        s = db.scalar(select(Session).where(Session.token == token, Session.kind == "study"))
        why = refusal(db, s) if s is not None else None
    return message_page(why) if why else static_page("participant.html")


@pages.get("/join/{link_token}")
def join_page(link_token: str, request: Request) -> Response:
    """The study link: the panel's participant id in the query creates or resumes that id's
    session (then the participant's page, with the query kept), or a page says why not."""
    query = dict(request.query_params)
    with request.app.state.db() as db:
        study_id = db.scalar(select(Study.id).where(Study.link_token == link_token))
        if study_id is None:
            return message_page("invalid")
        key, ids = panel_ids(study_config(db, study_id), query)
        got: Arrival = arrive(db, study_id, key, ids)
        if got.session is None:
            return message_page(got.page or "invalid")
        token = got.session.token
    log.info("study %s: panel id arrived through the study link", study_id)
    return RedirectResponse(f"/s/{token}?{urllib.parse.urlencode(query)}", status_code=303)


lifecycle = APIRouter(
    prefix="/api", tags=["experimenter"], dependencies=[Depends(require_experimenter)], responses=errors(400, 401, 403, 404, 409)
)


@lifecycle.post("/studies/{study_id}/status", summary="Open, pause or close a study")
def post_status(study_id: str, body: StatusIn, request: Request):
    with request.app.state.db() as db:
        st = study_or_404(db, study_id)
        set_status(db, st, body.status)
        log.info("study %s is now %s", st.id, st.status)
        return {"id": st.id, "status": st.status, "link": public_url(request, f"/join/{st.link_token}")}


@lifecycle.post("/studies/{study_id}/preview", status_code=201, summary="A preview of the participant's view, not recorded")
def post_preview(study_id: str, request: Request):
    """A preview session: the participant's view as a participant sees it (``?speed=`` works here
    only), run in the previews' own database (``preview.Previews``): nothing of it is stored with
    the study, so it is never exported, counted or balanced."""
    with request.app.state.db() as db:
        st = study_or_404(db, study_id)
        s = request.app.state.previews.start(st)
    return {"session_id": s.id, "link": session_link(request, s), "role": s.role}


@lifecycle.post("/studies/{study_id}/sessions/{session_id}/revoke", summary="Revoke a participant's link")
def post_revoke(study_id: str, session_id: str, request: Request):
    with request.app.state.db() as db:
        s = db.get(Session, session_id)
        if s is None or s.study_id != study_id:
            raise HTTPException(404, f"no session {session_id!r} in study {study_id!r}")
        revoke(db, s)
        request.app.state.tokens.pop(s.token)
        log.info("study %s: session %s revoked", study_id, s.id)
        return {"session_id": s.id, "revoked_at": iso(s.revoked_at)}
