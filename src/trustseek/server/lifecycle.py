"""A study's lifecycle and its participants' arrival.

A study is ``draft`` (links made now are pilots; the study link refuses arrivals), ``open``,
``paused`` (no new arrivals; started sessions go on) or ``closed`` (for good).  Sessions are
``participant`` or ``pilot`` sessions (left out of the analysis export unless asked for);
previews run in a database of their own (``preview``).  The study link gives every panel
participant one session, keyed by the panel's id (a unique constraint keeps it one under
concurrent arrivals; the study row is locked while an arrival is placed, so that block orders
stay balanced and the quota is exact).
"""

from __future__ import annotations

import secrets
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession

from ..model.core import TrustModel
from .answers import ended
from .errors import Conflict, NotAllowed
from .orm import Session, Study, try_commit, utcnow
from .sessions import new_session, study_config
from .studies import participant_plan

#: the states each state may move to
MOVES = {"draft": ("open", "closed"), "open": ("paused", "closed"), "paused": ("open", "closed"), "closed": ()}
STATUSES = tuple(MOVES)
#: the panels' names of a participant's id in a study link's query, first found wins when the
#: study names none (Prolific, MTurk, SONA)
PANEL_ID_PARAMS = ("PROLIFIC_PID", "workerId", "id")


def set_status(db: DBSession, study: Study, status: str) -> Study:
    """Move ``study`` to ``status`` (a move its lifecycle allows); commits."""
    if status not in STATUSES:
        raise NotAllowed(f"status must be one of {list(STATUSES)}, got {status!r}")
    if status != study.status and status not in MOVES[study.status]:
        allowed = list(MOVES[study.status]) or "none (a closed study stays closed)"
        raise Conflict(f"a {study.status} study cannot become {status}; allowed: {allowed}")
    study.status = status
    db.commit()
    return study


def counted(study_id: str):
    """The conditions of the sessions that count: participants of the study, not revoked."""
    return (Session.study_id == study_id, Session.role == "participant", Session.revoked_at.is_(None))


def progress(db: DBSession, study_id: str) -> dict[str, int]:
    """Sessions of a study: participants by status (revoked links apart), then pilots (previews
    stored by earlier versions left out)."""
    counts = dict.fromkeys(("new", "running", "done", "screened", "revoked", "pilot"), 0)
    rows = db.execute(
        select(Session.role, Session.status, Session.revoked_at).where(Session.study_id == study_id, Session.role != "preview")
    )
    for role, status, revoked_at in rows.all():
        key = role if role != "participant" else "revoked" if revoked_at is not None else status
        counts[key] = counts.get(key, 0) + 1
    return counts


def balanced_index(db: DBSession, study: Study) -> int:
    """The rotation (0-based) that the fewest counted sessions started with, the lowest of ties."""
    cfg = study_config(db, study.id)
    n = len(cfg["blocks"])
    plans = db.scalars(select(Session.plan).where(*counted(study.id))).all()
    used = Counter(p["block_order"][0] for p in plans)
    return min(range(n), key=lambda k: (used[k], k))


def create_participant(
    db: DBSession,
    study: Study,
    participant: str | None,
    role: str = "participant",
    panel_id: str | None = None,
    panel: dict[str, str] | None = None,
) -> Session:
    """A new session of ``study`` (not committed), its block order balanced over the counted sessions."""
    index = db.scalar(select(func.count()).select_from(Session).where(Session.study_id == study.id)) or 0
    label = participant or f"P{index + 1:03d}"
    if db.scalar(select(Session.id).where(Session.study_id == study.id, Session.participant == label)):
        raise Conflict(f"participant {label!r} already exists in study {study.id}")
    cfg = study_config(db, study.id)
    seed = int(np.random.default_rng().integers(0, 2**31 - 1))
    plan = participant_plan(cfg, balanced_index(db, study), seed)
    model = TrustModel.from_dict(cfg["model"])
    s = new_session(
        model.initial,
        kind="study",
        study_id=study.id,
        participant=label,
        seed=seed,
        secret=secrets.token_hex(16),
        plan=plan,
        status="new",
        role=role,
        panel_id=panel_id,
        panel=panel or None,
        speed=cfg["animation_speed"],
    )
    db.add(s)
    return s


def panel_ids(cfg: dict[str, Any], query: dict[str, str]) -> tuple[str | None, dict[str, str]]:
    """(the participant's panel id, every panel id of the query that the study keeps)."""
    names = list((cfg.get("panel") or {}).get("id_params") or PANEL_ID_PARAMS)
    ids = {k: query[k][:200] for k in names if query.get(k)}
    key = next((ids[k] for k in names if k in ids), None)
    return key, ids


@dataclass
class Arrival:
    """Where an arrival through the study link goes: a session to run, or a page (``page`` is
    ``completed``, ``closed``, ``paused``, ``draft``, ``full``, ``no-id`` or ``revoked``)."""

    session: Session | None = None
    page: str | None = None


def arrive(db: DBSession, study_id: str, panel_id: str | None, ids: dict[str, str]) -> Arrival:
    """Place an arrival through the study link: resume the panel id's session, or make one."""
    st = db.execute(select(Study).where(Study.id == study_id).with_for_update()).scalar_one()
    if not panel_id:
        db.rollback()
        return Arrival(page="no-id")
    old = _by_panel_id(db, study_id, panel_id)
    if old is not None:
        db.rollback()
        return _resumed(db, old)
    cfg = study_config(db, study_id)
    quota = cfg.get("quota")
    n = db.scalar(select(func.count()).select_from(Session).where(*counted(study_id))) or 0
    if quota is not None and n >= quota:  # every place taken: the study is full (and closed)
        st.status = "closed"
        db.commit()
        return Arrival(page="full")
    if st.status != "open":
        db.rollback()
        return Arrival(page=st.status)
    s = create_participant(db, st, None, panel_id=panel_id, panel=ids)
    if quota is not None and n + 1 >= quota:
        st.status = "closed"  # the last place is taken: the study closes
    try:
        db.commit()
    except IntegrityError:  # the same panel id arrived concurrently: take its session
        db.rollback()
        old = _by_panel_id(db, study_id, panel_id)
        if old is None:
            raise
        return _resumed(db, old)
    return Arrival(session=s)


def _by_panel_id(db: DBSession, study_id: str, panel_id: str) -> Session | None:
    return db.scalar(select(Session).where(Session.study_id == study_id, Session.panel_id == panel_id))


def _resumed(db: DBSession, s: Session) -> Arrival:
    if s.revoked_at is not None:
        return Arrival(page="revoked")
    assert s.study_id is not None
    if ended(db, s, study_config(db, s.study_id)):
        return Arrival(page="completed")
    return Arrival(session=s)


def refusal(db: DBSession, s: Session) -> str | None:
    """Why a session's link shows a page instead of the study (``revoked``, ``paused``,
    ``closed``: a study that takes no new arrivals, for a session not started), or None."""
    if s.revoked_at is not None:
        return "revoked"
    if s.status != "new" or s.role == "preview" or s.study_id is None:
        return None
    status = db.scalar(select(Study.status).where(Study.id == s.study_id))
    return status if status in ("paused", "closed") else None


def give_consent(db: DBSession, s: Session, cfg: dict[str, Any], query: dict[str, str]) -> bool:
    """Start session ``s`` (locked) on its participant's consent, keeping the panel's ids of the
    link's ``query``; whether it started now.  Commits."""
    started = s.status == "new"
    if started:
        why = refusal(db, s)
        if why is not None:
            db.rollback()
            raise Conflict(f"the study is {why}: it takes no new participants")
        key, ids = panel_ids(cfg, query) if cfg.get("panel") else (None, {})
        s.status, s.consented_at, s.updated_at = "running", utcnow(), utcnow()
        s.panel = {**ids, **(s.panel or {})} or None
        s.panel_id = s.panel_id or key
    elif ended(db, s, cfg):
        db.rollback()
        raise Conflict("this session has ended")
    if not try_commit(db):  # the same panel id already has a session of this study
        raise Conflict("this panel id already has a session in this study: use that session's link")
    return started


def revoke(db: DBSession, s: Session) -> Session:
    if s.revoked_at is None:
        s.revoked_at = s.updated_at = utcnow()
        db.commit()
    return s
