"""Database schema (SQLAlchemy 2 ORM), mirroring what the Alembic migrations in ``migrations/``
create: ``Study`` (configuration, lifecycle, panel link token), ``Session`` (a participant of a
study, ``kind = "study"``, or a robot of the deploy API, ``kind = "deploy"``: its live belief
and served trial, reached through its token), ``Trial`` (unique per session and number),
``Report`` (trust self-reports), ``Answer`` (questionnaire items), ``Event`` (UI events),
``EventBatch`` and ``PolicyBlob`` (a deploy policy, stored once by its hash)."""

from __future__ import annotations

from collections.abc import Iterable
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import JSON, Boolean, Float, ForeignKey, Index, Integer, Select, String, Text, UniqueConstraint, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column
from sqlalchemy.orm import Session as DBSession


def utcnow() -> datetime:
    return datetime.now(UTC).replace(tzinfo=None)


def iso(t: datetime | None) -> str | None:
    """A stored (UTC) time as the API and the exports write it: ISO 8601 ending in ``Z``."""
    return None if t is None else t.isoformat() + "Z"


def row_dict(row: Any, names: str | Iterable[str]) -> dict[str, Any]:
    """The columns ``names`` (or a space-separated string of them) of a row, by name."""
    return {c: getattr(row, c) for c in (names.split() if isinstance(names, str) else names)}


def token_session(db: DBSession, token: str) -> tuple[str, str] | None:
    """(id, kind) of the session whose token is ``token``, or None."""
    row = db.execute(select(Session.id, Session.kind).where(Session.token == token)).first()
    return None if row is None else (row.id, row.kind)


def try_commit(db: DBSession) -> bool:
    """Commit; False, rolled back, when a unique constraint refuses it (a concurrent request
    stored the same row first)."""
    try:
        db.commit()
    except IntegrityError:
        db.rollback()
        return False
    return True


class Base(DeclarativeBase):
    pass


class Study(Base):
    __tablename__ = "studies"

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    config: Mapped[dict] = mapped_column(JSON, deferred=True)  # large (solved policies): loaded on use
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    status: Mapped[str] = mapped_column(String(8), default="open")  # draft, open, paused, closed
    # the study link an online panel gives every participant: /join/<link_token>
    link_token: Mapped[str | None] = mapped_column(String(64), nullable=True)
    __table_args__ = (Index("uq_study_link_token", "link_token", unique=True),)


class PolicyBlob(Base):
    """A stored policy JSON, addressed by its SHA-256 (deploy sessions refer to it, so the
    frequently updated session rows stay small and identical policies are stored once)."""

    __tablename__ = "policies"

    sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    policy: Mapped[dict] = mapped_column(JSON)


class Session(Base):
    __tablename__ = "sessions"
    __table_args__ = (
        UniqueConstraint("study_id", "participant", name="uq_session_study_participant"),
        Index("uq_session_study_panel_id", "study_id", "panel_id", unique=True),
    )

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    token: Mapped[str] = mapped_column(String(64), unique=True, index=True)
    kind: Mapped[str] = mapped_column(String(16))  # "study" or "deploy"
    study_id: Mapped[str | None] = mapped_column(ForeignKey("studies.id"), index=True, nullable=True)
    participant: Mapped[str] = mapped_column(String(200))
    seed: Mapped[int] = mapped_column(Integer)
    # study sessions: the secret (hex) that outcomes and scene layouts are drawn from; never sent
    # to the participant's page (the experimenter's export holds it, to reproduce a session)
    secret: Mapped[str | None] = mapped_column(String(64), nullable=True)
    # online panels: the panel's ids taken from the participant link's query (PROLIFIC_PID, ...)
    panel: Mapped[dict | None] = mapped_column(JSON, nullable=True)
    # study sessions: block order and per-block complexity lists; deploy sessions: model/task/policy
    plan: Mapped[dict] = mapped_column(JSON, deferred=True)
    status: Mapped[str] = mapped_column(String(16), default="new")  # new, running, done
    consented_at: Mapped[datetime | None] = mapped_column(nullable=True)
    belief: Mapped[list] = mapped_column(JSON)  # the belief before the next trial
    trials_done: Mapped[int] = mapped_column(Integer, default=0)
    score: Mapped[float] = mapped_column(Float, default=0.0)
    # the trial currently served (decided, not yet committed)
    pending_trial: Mapped[int | None] = mapped_column(Integer, nullable=True)
    pending_complexity: Mapped[str | None] = mapped_column(String(32), nullable=True)
    pending_action: Mapped[str | None] = mapped_column(String(16), nullable=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow)
    # participant, pilot (left out of the analysis export unless asked for) or preview (never exported)
    role: Mapped[str] = mapped_column(String(12), default="participant")
    # the panel's participant id of a session made through the study link (one session per id)
    panel_id: Mapped[str | None] = mapped_column(String(200), nullable=True)
    speed: Mapped[float | None] = mapped_column(Float, nullable=True)  # the animation speed it ran at
    revoked_at: Mapped[datetime | None] = mapped_column(nullable=True)
    ended_at: Mapped[datetime | None] = mapped_column(nullable=True)
    # the comprehension quiz: {"attempts": [{"answers", "wrong", "at"}], "outcome": passed | failed | None}
    quiz: Mapped[dict | None] = mapped_column(JSON, nullable=True)


class _SessionRow:
    """The columns of a row that belongs to a session: an id, the session (indexed) and the time
    it was made (listed last)."""

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True, sort_order=-2)
    session_id: Mapped[str] = mapped_column(ForeignKey("sessions.id"), index=True, sort_order=-1)
    created_at: Mapped[datetime] = mapped_column(default=utcnow, sort_order=1)


class Trial(_SessionRow, Base):
    __tablename__ = "trials"
    __table_args__ = (UniqueConstraint("session_id", "trial", name="uq_trial_session_number"),)

    trial: Mapped[int] = mapped_column(Integer)
    block: Mapped[int] = mapped_column(Integer)
    policy: Mapped[str] = mapped_column(String(32))
    complexity: Mapped[str] = mapped_column(String(32))
    robot_action: Mapped[str] = mapped_column(String(16))
    human_action: Mapped[str | None] = mapped_column(String(16), nullable=True)
    outcome: Mapped[str] = mapped_column(String(16))
    experience: Mapped[str] = mapped_column(String(16))
    reward: Mapped[float] = mapped_column(Float)
    belief: Mapped[float | None] = mapped_column(Float, nullable=True)  # P(trust=high) at the decision
    belief_after: Mapped[float | None] = mapped_column(Float, nullable=True)
    effort_ms: Mapped[float | None] = mapped_column(Float, nullable=True)
    practice: Mapped[bool] = mapped_column(Boolean, default=False)  # practice trials: logged, not analysed
    submission_id: Mapped[str] = mapped_column(String(64))


#: a committed trial's columns as the API answers them (``sessions.trial_dict``), and as the
#: decision API's store reads them (``deploy.store``)
TRIAL_FIELDS = tuple(c.name for c in Trial.__table__.c if c.name not in ("id", "session_id", "practice", "created_at"))


class Report(_SessionRow, Base):
    __tablename__ = "reports"
    __table_args__ = (UniqueConstraint("session_id", "after_trial", name="uq_report_session_trial"),)

    after_trial: Mapped[int] = mapped_column(Integer)
    block: Mapped[int] = mapped_column(Integer)
    scope: Mapped[str] = mapped_column(String(8))  # "trial" or "block"
    value: Mapped[float] = mapped_column(Float)


class Answer(_SessionRow, Base):
    """One item of a questionnaire (``docs/experiments.md``), answered after trial ``after_trial``."""

    __tablename__ = "answers"
    __table_args__ = (UniqueConstraint("session_id", "questionnaire", "after_trial", "item", name="uq_answer"),)

    questionnaire: Mapped[str] = mapped_column(String(100))
    when: Mapped[str] = mapped_column(String(8))  # "trial", "block" or "end"
    after_trial: Mapped[int] = mapped_column(Integer)
    block: Mapped[int] = mapped_column(Integer)
    item: Mapped[str] = mapped_column(String(100))
    value: Mapped[float] = mapped_column(Float)


class Event(_SessionRow, Base):
    __tablename__ = "events"

    trial: Mapped[int | None] = mapped_column(Integer, nullable=True)
    client_time: Mapped[float | None] = mapped_column(Float, nullable=True)  # ms since the Unix epoch
    page: Mapped[str | None] = mapped_column(String(32), nullable=True)  # the page load that made it
    type: Mapped[str] = mapped_column(String(40))
    data: Mapped[str] = mapped_column(Text, default="{}")


class EventBatch(Base):
    """A batch of UI events posted with a client-made id: a batch posted again (a retry whose
    first answer was lost) is stored once."""

    __tablename__ = "event_batches"

    session_id: Mapped[str] = mapped_column(ForeignKey("sessions.id"), primary_key=True)
    batch: Mapped[str] = mapped_column(String(64), primary_key=True)
    events: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


def session_rows(table: Any, where: Iterable[Any], *columns: Any) -> Select:
    """``columns`` (by default the whole rows) of ``table``, joined to their sessions (whose
    columns may be among them), of the sessions that meet the conditions ``where``."""
    return select(*(columns or (table,))).join(Session, table.session_id == Session.id).where(*where)
