"""Tokens: the experimenter token (studies, dashboard, export, opening deploy sessions) and
the per-session tokens (a participant or a robot reaches only its own session)."""

from __future__ import annotations

import secrets
from dataclasses import dataclass
from typing import Any

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from .orm import token_session

bearer = HTTPBearer(auto_error=False, description="Experimenter token, or a session token for session endpoints.")

#: the refusal of a request without a bearer token (401)
MISSING_TOKEN = "missing token: send 'Authorization: Bearer <token>'"


def bearer_token(header: str) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` header, or None."""
    scheme, _, token = header.partition(" ")
    token = token.strip()
    return token if scheme.lower() == "bearer" and token else None


def token_of(creds: HTTPAuthorizationCredentials | None) -> str:
    if creds is None or not creds.credentials:
        raise HTTPException(401, MISSING_TOKEN, headers={"WWW-Authenticate": "Bearer"})
    return creds.credentials


async def require_experimenter(request: Request, creds: HTTPAuthorizationCredentials | None = Depends(bearer)) -> None:
    if not secrets.compare_digest(token_of(creds).encode(), request.app.state.token.encode()):
        raise HTTPException(403, "wrong experimenter token")


@dataclass(frozen=True)
class Caller:
    """The session a token belongs to (tokens never change, so this is cached per process); a
    preview's session is in the previews' database (``preview.Previews``)."""

    id: str
    kind: str
    preview: bool = False


def caller_for_token(state: Any, token: str) -> Caller | None:
    """The session of a session token, or None; ``state`` is the application's state."""
    caller = state.tokens.get(token)
    if caller is None:
        with state.db() as db:
            found = token_session(db, token)
        preview = found is None
        found = state.previews.find(token) if preview else found
        if found is None:
            return None
        caller = state.tokens.put(token, Caller(found[0], found[1], preview=preview))
    return caller


async def require_session(
    session_id: str, request: Request, creds: HTTPAuthorizationCredentials | None = Depends(bearer)
) -> Caller:
    """The session named in the path, if the bearer token is that session's token."""
    return session_caller(request, token_of(creds), session_id)


def session_caller(request: Request, token: str, session_id: str | None = None) -> Caller:
    """The session of ``token``, if it is session ``session_id`` (when one is named)."""
    s = caller_for_token(request.app.state, token)
    if s is None:
        raise HTTPException(401, "unknown session token")
    if session_id is not None and not secrets.compare_digest(s.id.encode(), session_id.encode()):
        raise HTTPException(403, "this token belongs to another session")
    return s
