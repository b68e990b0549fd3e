"""A study's tables, the one writer of their CSV and Parquet, and the data bundle: every table
in both formats, the configuration and a data dictionary (``DICTIONARY``, which also orders
every table's columns), in a folder (``trustseek export STUDY --bundle DIR``) or a zip file.

The trial log (``trials``) is what ``trustseek fit`` reads: the canonical columns, then the
study's.  Practice trials are left out of it by default; its ``trial`` counts the analysed
trials from 1, ``session_trial`` the session's (practice included: the numbering of events and
reports).  Pilot sessions are left out unless asked for (``pilot``); preview sessions always.
"""

from __future__ import annotations

import io
import json
import zipfile
from collections import Counter
from pathlib import Path
from typing import Any

import pandas as pd
from sqlalchemy import func, select
from sqlalchemy.orm import Session as DBSession

from ..vocab import TRIAL_COLUMNS
from .answers import check_passed, quiz_attempts
from .orm import Answer, Event, Report, Session, Study, Trial, iso, row_dict, session_rows
from .studies import practice_count

#: the meaning of every column of the bundle, by table
DICTIONARY: dict[str, dict[str, str]] = {
    "trials": {
        "participant": "participant label (P001, ...; the panel id is in sessions)",
        "trial": "analysed trial, from 1 (practice left out)",
        "complexity": "item complexity: low or high",
        "robot_action": "autonomous or ask",
        "human_action": "rely or intervene; when the robot asked, the human teleoperated, recorded as intervene",
        "experience": "reliable or faulty (Section III)",
        "block": "block number in the study's order of blocks, from 1",
        "block_name": "the block's name",
        "policy": "the block's policy kind",
        "outcome": "success, collision, dropped or teleoperated",
        "reward": "points of the trial, eq. (1)",
        "belief": "P(trust = high) when the action was decided",
        "belief_after": "P(trust = high) after the trial's update",
        "effort_ms": "teleoperation time in ms (empty when the robot worked alone)",
        "self_report": "the 0-100 trust self-report after this trial (or block), if any",
        "study": "study id",
        "session": "session id",
        "committed_at": "server time the trial was stored (UTC)",
        "practice": "practice trial (false in the analysis log)",
        "session_trial": "trial number in the session, practice included (the numbering of events)",
    },
    "reports": {
        "participant": "participant label",
        "trial": "analysed trial the answer follows (joins trials on participant, trial)",
        "session_trial": "session trial it follows",
        "block": "block number, from 1",
        "block_name": "the block's name",
        "questionnaire": "questionnaire name; self_report is the 0-100 slider",
        "when": "trial, block or end",
        "item": "item id (trust for the slider)",
        "value": "the answer (a point of the scale)",
        "reverse": "reverse-scored item",
        "check": "an attention check: the point the item instructs (empty otherwise)",
        "check_passed": "the answer is the instructed point (empty when not a check)",
        "study": "study id",
        "session": "session id",
        "answered_at": "server time (UTC)",
    },
    "questionnaires": {
        "questionnaire": "questionnaire name (quiz: the comprehension quiz)",
        "when": "trial, block, end (quiz: after the instructions)",
        "title": "title shown",
        "item": "item or question id",
        "text": "the text shown",
        "reverse": "reverse-scored item",
        "check": "attention check: the instructed point; quiz: the right option's index",
        "scale_min": "lowest point of the scale",
        "scale_max": "highest point of the scale",
        "options": "quiz: the options, as JSON",
    },
    "quiz": {
        "participant": "participant label",
        "session": "session id",
        "attempt": "attempt number, from 1",
        "question": "question id",
        "answer": "index of the chosen option",
        "correct": "the chosen option is the right one",
        "answered_at": "server time (UTC)",
    },
    "sessions": {
        "participant": "participant label",
        "session": "session id",
        "role": "participant or pilot",
        "status": "new, running, done or screened (ended by a failed quiz)",
        "trials_done": "trials committed, practice included",
        "score": "team score",
        "seed": "the session's seed (reproduces its plan and actions)",
        "secret": "the session's secret (reproduces its outcomes and scenes)",
        "block_order": "block names in the participant's order, as JSON",
        "panel_id": "the panel's participant id (PROLIFIC_PID, workerId, ...)",
        "panel": "every panel id of the link, as JSON",
        "speed": "animation speed the session ran at",
        "created_at": "arrival (UTC)",
        "started_at": "consent (UTC)",
        "ended_at": "end (UTC)",
        "revoked_at": "link revoked (UTC)",
        "quiz_attempts": "attempts at the comprehension quiz",
        "quiz_outcome": "passed or failed (empty: no quiz, or not finished)",
        "checks_failed": "attention-check items answered otherwise than instructed",
        "pages": "page loads that sent events (more than 1: the participant reloaded the page or opened a second tab; "
        "empty: events stored before events named their page)",
    },
    "events": {
        "participant": "participant label",
        "session": "session id",
        "trial": "session trial (empty outside trials)",
        "client_time": "browser time, ms since the Unix epoch",
        "page": "the page load that sent the event (a reload or a second tab of the session is another)",
        "server_time": "server time (UTC)",
        "type": "event type (consent, trial_start, intervene, grasp, deposit, outcome_shown, ...)",
        "data": "the event's data, as JSON",
    },
}


TABLES = tuple(DICTIONARY)
assert list(DICTIONARY["trials"])[: len(TRIAL_COLUMNS)] == list(TRIAL_COLUMNS)

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


def _block_names(study: Study) -> list[str]:
    return [b["name"] for b in study.config["blocks"]] + ["practice"]


def _items(study: Study) -> dict[tuple[str, str], dict[str, Any]]:
    """The study's questionnaire items by (questionnaire, item id)."""
    return {(q["name"], i["id"]): i for q in study.config.get("questionnaires") or () for i in q["items"]}


def trials_frame(db: DBSession, study: Study, practice: bool = False, pilot: bool = False) -> pd.DataFrame:
    """The study's trial log: the analysed trials, or every trial with ``practice=True``; pilot
    sessions with ``pilot=True``."""
    names = _block_names(study)
    skip = practice_count(study.config)  # the practice trials come first in every session
    trials = session_rows(Trial, exported(study, pilot), Trial, Session.participant)
    if not practice:
        trials = trials.where(Trial.practice.is_(False))
    rows = db.execute(trials.order_by(Session.participant, Trial.trial)).all()
    reports = {(r.session_id, r.after_trial): r.value for r in db.scalars(session_rows(Report, exported(study, pilot)))}
    data = [
        {
            **row_dict(t, "complexity robot_action human_action experience policy outcome reward belief belief_after effort_ms"),
            "participant": p,
            "trial": t.trial if practice else t.trial - skip,
            "block": t.block + 1,
            "block_name": names[t.block],
            "self_report": reports.get((t.session_id, t.trial)),
            "study": study.id,
            "session": t.session_id,
            "committed_at": iso(t.created_at),
            "practice": bool(t.practice),
            "session_trial": t.trial,
        }
        for t, p in rows
    ]
    frame = pd.DataFrame(data, columns=list(DICTIONARY["trials"]))
    text = dict.fromkeys(("participant", "complexity", "robot_action", "human_action", "experience"), "object")
    return frame.astype({"trial": "int64", "block": "int64", **text, "self_report": "float64", "effort_ms": "float64"})


def answers_frame(db: DBSession, study: Study, pilot: bool = False) -> pd.DataFrame:
    """Every self-report (0-100 slider, questionnaire ``self_report``, item ``trust``) and every
    questionnaire item, one row each, next to the analysed trial each follows."""
    names, skip, items = _block_names(study), practice_count(study.config), _items(study)

    def row(r: Report | Answer, p: str, questionnaire: str, when: str, item: str, asked: dict[str, Any]) -> dict[str, Any]:
        return {
            "participant": p,
            "trial": r.after_trial - skip,
            "session_trial": r.after_trial,
            "block": r.block + 1,
            "block_name": names[r.block],
            "questionnaire": questionnaire,
            "when": when,
            "item": item,
            "value": r.value,
            "reverse": bool(asked.get("reverse")),
            "check": asked.get("check"),
            "check_passed": check_passed(asked, r.value),
            "study": study.id,
            "session": r.session_id,
            "answered_at": iso(r.created_at),
        }

    reports = db.execute(session_rows(Report, exported(study, pilot), Report, Session.participant))
    answers = db.execute(session_rows(Answer, exported(study, pilot), Answer, Session.participant))
    rows = [row(r, p, "self_report", r.scope, "trust", {}) for r, p in reports]
    rows += [row(a, p, a.questionnaire, a.when, a.item, items.get((a.questionnaire, a.item), {})) for a, p in answers]
    frame = pd.DataFrame(rows, columns=list(DICTIONARY["reports"]))
    frame = frame.sort_values(["participant", "session_trial", "questionnaire"], kind="stable").reset_index(drop=True)
    return frame.astype({"trial": "int64", "value": "float64", "check": "Int64", "check_passed": "boolean"})


def sessions_frame(db: DBSession, study: Study, pilot: bool = False) -> pd.DataFrame:
    """One row per participant: status, the panel's ids (JSON) and the seed and secret that
    reproduce the session's plan, actions, outcomes and scenes."""
    names = _block_names(study)
    items = _items(study)
    answers = db.scalars(session_rows(Answer, exported(study, pilot)))
    failed = Counter(a.session_id for a in answers if check_passed(items.get((a.questionnaire, a.item), {}), a.value) is False)
    # page loads per session: unknown (empty) for a session whose events came without one (stored
    # before events named their page), 0 for a session that sent no event
    loads = session_rows(Event, exported(study, pilot), Event.session_id, func.count(Event.page.distinct()), func.count())
    pages = {sid: n if n or not total else None for sid, n, total in db.execute(loads.group_by(Event.session_id))}
    rows = [
        {
            **row_dict(s, "participant role status trials_done score seed secret panel_id speed"),
            "session": s.id,
            "block_order": json.dumps([names[b] for b in s.plan["block_order"]]),
            "panel": json.dumps(s.panel or {}),
            "created_at": iso(s.created_at),
            "started_at": iso(s.consented_at),
            "ended_at": iso(s.ended_at),
            "revoked_at": iso(s.revoked_at),
            "quiz_attempts": len(quiz_attempts(s)),
            "quiz_outcome": (s.quiz or {}).get("outcome"),
            "checks_failed": failed.get(s.id, 0),
            "pages": pages.get(s.id, 0),
        }
        for s in db.scalars(select(Session).where(*exported(study, pilot)).order_by(Session.participant))
    ]
    return pd.DataFrame(rows, columns=list(DICTIONARY["sessions"])).astype({"pages": "Int64"})


def events_frame(db: DBSession, study: Study, pilot: bool = False) -> pd.DataFrame:
    events = session_rows(Event, exported(study, pilot), Event, Session.participant)
    rows = db.execute(events.order_by(Session.participant, Event.id)).all()
    data = [
        {
            **row_dict(e, "trial client_time page type data"),
            "participant": p,
            "session": e.session_id,
            "server_time": iso(e.created_at),
        }
        for e, p in rows
    ]
    return pd.DataFrame(data, columns=list(DICTIONARY["events"])).astype({"trial": "Int64"})


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


def questionnaires_frame(study: Study) -> pd.DataFrame:
    """Every questionnaire item and quiz question as asked."""
    cfg = study.config
    questionnaires = [
        {
            "questionnaire": q["name"],
            "when": q["when"],
            "title": q.get("title"),
            "item": i["id"],
            "text": i["text"],
            "reverse": bool(i.get("reverse")),
            "check": i.get("check"),
            "scale_min": q["scale"]["min"],
            "scale_max": q["scale"]["max"],
            "options": None,
        }
        for q in cfg.get("questionnaires") or ()
        for i in q["items"]
    ]
    quiz = [
        {
            "questionnaire": "quiz",
            "when": "instructions",
            "title": None,
            "item": qq["id"],
            "text": qq["text"],
            "reverse": False,
            "check": qq["answer"],
            "scale_min": None,
            "scale_max": None,
            "options": json.dumps(qq["options"]),
        }
        for qq in (cfg.get("quiz") or {}).get("questions", [])
    ]
    frame = pd.DataFrame(questionnaires + quiz, columns=list(DICTIONARY["questionnaires"]))
    return frame.astype(dict.fromkeys(("check", "scale_min", "scale_max"), "Int64"))


def quiz_frame(db: DBSession, study: Study, pilot: bool = False) -> pd.DataFrame:
    answers = {q["id"]: q["answer"] for q in (study.config.get("quiz") or {}).get("questions", [])}
    rows = [
        {
            "participant": s.participant,
            "session": s.id,
            "attempt": k + 1,
            "question": q,
            "answer": a,
            "correct": a == answers.get(q),
            "answered_at": at["at"],
        }
        for s in db.scalars(select(Session).where(*exported(study, pilot)).order_by(Session.participant))
        for k, at in enumerate(quiz_attempts(s))
        for q, a in at["answers"].items()
    ]
    return pd.DataFrame(rows, columns=list(DICTIONARY["quiz"]))


def bundle_frames(db: DBSession, study: Study, pilot: bool = False) -> dict[str, pd.DataFrame]:
    return {
        "trials": trials_frame(db, study, pilot=pilot),
        "reports": answers_frame(db, study, pilot),
        "questionnaires": questionnaires_frame(study),
        "quiz": quiz_frame(db, study, pilot),
        "sessions": sessions_frame(db, study, pilot),
        "events": events_frame(db, study, pilot),
    }


def dictionary_frame(frames: dict[str, pd.DataFrame]) -> pd.DataFrame:
    rows = [
        {"table": t, "column": c, "type": str(f[c].dtype), "description": DICTIONARY[t].get(c, "")}
        for t, f in frames.items()
        for c in f.columns
    ]
    return pd.DataFrame(rows, columns=["table", "column", "type", "description"])


def bundle_files(db: DBSession, study: Study, pilot: bool = False) -> dict[str, bytes]:
    """The bundle's files by name: ``<table>.csv`` and ``<table>.parquet`` for every table,
    ``study.json`` and ``dictionary.csv``."""
    frames = bundle_frames(db, study, pilot)
    files: dict[str, bytes] = {}
    for name, frame in frames.items():
        # the trial log as trustseek fit reads it; the other tables hold text from participants'
        # browsers: formulas escaped, CR/LF quoted
        files[f"{name}.csv"] = table_bytes(frame, "csv", escaped=name != "trials")
        files[f"{name}.parquet"] = table_bytes(frame, "parquet")
    files["study.json"] = json.dumps({"id": study.id, "name": study.name, "config": study.config}, indent=2).encode()
    files["dictionary.csv"] = table_bytes(dictionary_frame(frames), "csv")
    return files


def write_bundle(files: dict[str, bytes], folder: Path) -> None:
    for name, content in files.items():
        (folder / name).write_bytes(content)


def bundle_zip(files: dict[str, bytes], root: str) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, content in files.items():
            z.writestr(f"{root}/{name}", content)
    return buf.getvalue()
