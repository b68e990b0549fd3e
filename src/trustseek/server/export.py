"""Export a study to the canonical trial-log format (what ``trustseek fit`` reads) and its
UI events to an events table.

Trial columns: ``participant, trial, complexity, robot_action, human_action, experience``
(canonical, in that order), then ``block, block_name, policy, outcome, reward, belief,
belief_after, effort_ms, self_report, study, session, committed_at, practice, session_trial``.
``belief`` is P(trust = high) when the action was decided, ``belief_after`` after the trial's
update.  When the robot asks, the human teleoperates, recorded as ``intervene``.

Practice trials are left out of the analysis log (the default), whose ``trial`` counts the
analysed trials from 1; ``session_trial`` is the trial's number in the session (practice
included), the numbering of the events, the full log (``practice=True``) and the reports.

The reports table is long: one row per self-report or questionnaire item, with the analysed
trial it follows (``trial``, empty after practice) so that it joins the trial log.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import pandas as pd
from sqlalchemy import Select, select
from sqlalchemy.orm import Session as DBSession

from ..vocab import TRIAL_COLUMNS
from .answers import check_passed
from .orm import Answer, Event, Report, Session, Study, Trial, iso

CANONICAL = list(TRIAL_COLUMNS)
EXTRA = [
    "block",
    "block_name",
    "policy",
    "outcome",
    "reward",
    "belief",
    "belief_after",
    "effort_ms",
    "self_report",
    "study",
    "session",
    "committed_at",
    "practice",
    "session_trial",
]
REPORT_COLUMNS = [
    "participant",
    "trial",
    "session_trial",
    "block",
    "block_name",
    "questionnaire",
    "when",
    "item",
    "value",
    "reverse",
    "check",
    "check_passed",
    "study",
    "session",
    "answered_at",
]
SESSION_COLUMNS = [
    "participant",
    "session",
    "role",
    "status",
    "trials_done",
    "score",
    "seed",
    "secret",
    "block_order",
    "panel_id",
    "panel",
    "speed",
    "created_at",
    "started_at",
    "ended_at",
    "revoked_at",
    "quiz_attempts",
    "quiz_outcome",
    "checks_failed",
]
EVENT_COLUMNS = ["participant", "session", "trial", "client_time", "server_time", "type", "data"]

#: a text cell starting with one of these is a formula to a spreadsheet (CSV injection)
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def escape_formulas(frame: pd.DataFrame) -> pd.DataFrame:
    """A copy of ``frame`` in which every text cell that a spreadsheet would read as a formula
    (starting with ``= + - @``, a tab or a carriage return) is prefixed with ``'``, the
    spreadsheets' mark for literal text.  Numbers are left as they are.  Used for the CSV of
    the events table, whose text comes from participants' browsers."""
    out = frame.copy()
    for col in out.columns:
        if not pd.api.types.is_numeric_dtype(out[col]):
            out[col] = out[col].map(lambda v: "'" + v if isinstance(v, str) and v.startswith(FORMULA_START) else v)
    return out


def exported(study: Study, pilot: bool = False) -> tuple:
    """The conditions of the sessions a table holds: the study's participants, and its pilots
    when asked for (``pilot``); preview sessions never."""
    return (Session.study_id == study.id, Session.role.in_(("participant", "pilot") if pilot else ("participant",)))


def _exported_rows(table, study: Study, pilot: bool, *columns) -> Select:
    """The rows of ``table`` (with ``columns`` of their session) of the sessions a table holds."""
    return select(table, *columns).join(Session, table.session_id == Session.id).where(*exported(study, pilot))


def _block_names(study: Study) -> list[str]:
    return [b["name"] for b in study.config["blocks"]] + ["practice"]


def _practice_counts(db: DBSession, study: Study) -> dict[str, int]:
    """Practice trials per session (they come first, so analysed trial = session trial - count)."""
    n = len((study.config.get("practice") or {}).get("trials", []))
    return dict.fromkeys(db.scalars(select(Session.id).where(Session.study_id == study.id)), n)


def trials_frame(db: DBSession, study: Study, practice: bool = False, pilot: bool = False) -> pd.DataFrame:
    """The study's trial log: the analysed trials, or every trial with ``practice=True``; pilot
    sessions with ``pilot=True``."""
    names = _block_names(study)
    skip = _practice_counts(db, study)
    trials = _exported_rows(Trial, study, pilot, Session.participant)
    if not practice:
        trials = trials.where(Trial.practice.is_(False))
    rows = db.execute(trials.order_by(Session.participant, Trial.trial)).all()
    reports = {(r.session_id, r.after_trial): r.value for r in db.scalars(_exported_rows(Report, study, pilot))}
    data = [
        {
            "participant": p,
            "trial": t.trial if practice else t.trial - skip.get(t.session_id, 0),
            "complexity": t.complexity,
            "robot_action": t.robot_action,
            "human_action": t.human_action,
            "experience": t.experience,
            "block": t.block + 1,
            "block_name": names[t.block],
            "policy": t.policy,
            "outcome": t.outcome,
            "reward": t.reward,
            "belief": t.belief,
            "belief_after": t.belief_after,
            "effort_ms": t.effort_ms,
            "self_report": reports.get((t.session_id, t.trial)),
            "study": study.id,
            "session": t.session_id,
            "committed_at": iso(t.created_at),
            "practice": bool(t.practice),
            "session_trial": t.trial,
        }
        for t, p in rows
    ]
    frame = pd.DataFrame(data, columns=CANONICAL + EXTRA)
    text = dict.fromkeys(("participant", "complexity", "robot_action", "human_action", "experience"), "object")
    return frame.astype({"trial": "int64", "block": "int64", **text, "self_report": "float64", "effort_ms": "float64"})


def answers_frame(db: DBSession, study: Study, pilot: bool = False) -> pd.DataFrame:
    """Every self-report (0-100 slider, questionnaire ``self_report``, item ``trust``) and every
    questionnaire item, one row each, next to the analysed trial each follows."""
    names = _block_names(study)
    skip = _practice_counts(db, study)
    items = {(q["name"], i["id"]): i for q in study.config.get("questionnaires") or () for i in q["items"]}
    data: list[tuple[str, str, str, float, dict, Report | Answer, str]] = []
    for r, p in db.execute(_exported_rows(Report, study, pilot, Session.participant)).all():
        data.append(("self_report", r.scope, "trust", r.value, {}, r, p))
    for a, p in db.execute(_exported_rows(Answer, study, pilot, Session.participant)).all():
        data.append((a.questionnaire, a.when, a.item, a.value, items.get((a.questionnaire, a.item), {}), a, p))
    rows = [
        {
            "participant": p,
            "trial": r.after_trial - skip.get(r.session_id, 0),
            "session_trial": r.after_trial,
            "block": r.block + 1,
            "block_name": names[r.block],
            "questionnaire": q,
            "when": when,
            "item": item,
            "value": value,
            "reverse": bool(item_.get("reverse")),
            "check": item_.get("check"),
            "check_passed": check_passed(item_, value),
            "study": study.id,
            "session": r.session_id,
            "answered_at": iso(r.created_at),
        }
        for q, when, item, value, item_, r, p in data
    ]
    frame = pd.DataFrame(rows, columns=REPORT_COLUMNS)
    frame = frame.sort_values(["participant", "session_trial", "questionnaire"], kind="stable").reset_index(drop=True)
    return frame.astype({"trial": "int64", "value": "float64", "check": "Int64", "check_passed": "boolean"})


def sessions_frame(db: DBSession, study: Study, pilot: bool = False) -> pd.DataFrame:
    """One row per participant: status, the panel's ids (JSON) and the seed and secret that
    reproduce the session's plan, actions, outcomes and scenes."""
    names = _block_names(study)
    checks = study.config.get("questionnaires") or ()
    items = {(q["name"], i["id"]): i for q in checks for i in q["items"] if i.get("check") is not None}
    failed: dict[str, int] = {}
    for a in db.scalars(_exported_rows(Answer, study, pilot)):
        if (a.questionnaire, a.item) in items and not check_passed(items[(a.questionnaire, a.item)], a.value):
            failed[a.session_id] = failed.get(a.session_id, 0) + 1
    rows = [
        {
            "participant": s.participant,
            "session": s.id,
            "role": s.role,
            "status": s.status,
            "trials_done": s.trials_done,
            "score": s.score,
            "seed": s.seed,
            "secret": s.secret,
            "block_order": json.dumps([names[b] for b in s.plan["block_order"]]),
            "panel_id": s.panel_id,
            "panel": json.dumps(s.panel or {}),
            "speed": s.speed,
            "created_at": iso(s.created_at),
            "started_at": iso(s.consented_at),
            "ended_at": iso(s.ended_at),
            "revoked_at": iso(s.revoked_at),
            "quiz_attempts": len((s.quiz or {}).get("attempts", [])),
            "quiz_outcome": (s.quiz or {}).get("outcome"),
            "checks_failed": failed.get(s.id, 0),
        }
        for s in db.scalars(select(Session).where(*exported(study, pilot)).order_by(Session.participant))
    ]
    return pd.DataFrame(rows, columns=SESSION_COLUMNS)


def events_frame(db: DBSession, study: Study, pilot: bool = False) -> pd.DataFrame:
    rows = db.execute(_exported_rows(Event, study, pilot, Session.participant).order_by(Session.participant, Event.id)).all()
    data = [
        {
            "participant": p,
            "session": e.session_id,
            "trial": e.trial,
            "client_time": e.client_time,
            "server_time": iso(e.created_at),
            "type": e.type,
            "data": e.data,
        }
        for e, p in rows
    ]
    frame = pd.DataFrame(data, columns=EVENT_COLUMNS)
    frame["trial"] = frame["trial"].astype("Int64")
    return frame


def table_bytes(frame: pd.DataFrame, fmt: str, escaped: bool = False) -> bytes:
    """A table as a file's bytes, CSV or Parquet: the one writer of the export, the bundle and
    ``trustseek export``.  ``escaped``: a table holding participants' text, whose CSV has its
    formulas escaped (:func:`escape_formulas`) and lines ended with CRLF (RFC 4180), so that a
    carriage return inside a participant's text is quoted instead of splitting the row."""
    if fmt == "parquet":
        buf = io.BytesIO()
        frame.to_parquet(buf, index=False)
        return buf.getvalue()
    if escaped:
        return escape_formulas(frame).to_csv(index=False, lineterminator="\r\n").encode()
    return frame.to_csv(index=False).encode()


def write_frame(frame: pd.DataFrame, path: str | Path) -> None:
    """Write a table by the suffix of ``path``: Parquet (``.parquet``, ``.pq``) or CSV."""
    path = Path(path)
    path.write_bytes(table_bytes(frame, "parquet" if path.suffix.lower() in (".parquet", ".pq") else "csv"))
