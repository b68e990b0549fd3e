"""A study's data bundle: every table in CSV and Parquet, the study's configuration and a data
dictionary, in one folder (``trustseek export STUDY --bundle DIR``) or one zip file (the
dashboard's download).

* ``trials``: the analysis trial log (``trustseek fit`` reads it as it is; its ``self_report``
  column is the rating ``trustseek validate --rating self_report`` reads);
* ``reports``: every self-report and questionnaire answer, one row each (long), with attention
  checks; ``questionnaires``: every item as asked (text, scale, reverse, check) and the quiz's
  questions; ``quiz``: every attempt at the comprehension quiz, one row per question;
* ``sessions``: one row per participant with the panel ids, times, speed and checks;
* ``events``: the interface's events; ``study.json``: the study's configuration;
  ``dictionary.csv``: table, column, type and meaning of every column.

Pilot sessions are left out unless asked for (``pilot``); preview sessions always.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import pandas as pd
from sqlalchemy import select
from sqlalchemy.orm import Session as DBSession

from .export import answers_frame, events_frame, exported, sessions_frame, table_bytes, trials_frame
from .orm import Session, Study

TABLES = ("trials", "reports", "questionnaires", "quiz", "sessions", "events")

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
    },
    "events": {
        "participant": "participant label",
        "session": "session id",
        "trial": "session trial (empty outside trials)",
        "client_time": "browser time, ms since the Unix epoch",
        "server_time": "server time (UTC)",
        "type": "event type (consent, trial_start, intervene, grasp, deposit, outcome_shown, ...)",
        "data": "the event's data, as JSON",
    },
}


def questionnaires_frame(study: Study) -> pd.DataFrame:
    """Every questionnaire item and quiz question as asked."""
    cfg = study.config
    rows = [
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
    for qq in (cfg.get("quiz") or {}).get("questions", []):
        rows.append(
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
        )
    frame = pd.DataFrame(rows, columns=list(DICTIONARY["questionnaires"]))
    for col in ("check", "scale_min", "scale_max"):
        frame[col] = frame[col].astype("Int64")
    return frame


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
        for k, at in enumerate((s.quiz or {}).get("attempts", []))
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
