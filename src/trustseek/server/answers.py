"""A study session's answers: the comprehension quiz, trust self-reports and questionnaires,
when each is due, and when the session is over (every trial committed, nothing left to answer).
A repeat of stored answers is a duplicate; different ones are refused.  Every quiz attempt is
kept with the session; after the last failed one the study's ``on_fail`` decides: ``end``
screens the session out, ``continue`` records the failure.  An attention-check item names the
point of its scale that it instructs.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session as DBSession

from .errors import Conflict, NotAllowed, NotFound
from .orm import Answer, Report, Session, iso, try_commit, utcnow

#: a session's status once a failed quiz has ended it
SCREENED = "screened"


def quiz_attempts(s: Session) -> list[dict[str, Any]]:
    """The session's attempts at the quiz so far: {"answers", "wrong", "at"} each."""
    return (s.quiz or {}).get("attempts", [])


def quiz_due(s: Session, cfg: dict[str, Any]) -> dict[str, Any] | None:
    """The quiz as the participant's page shows it (no answers), while it is still to be
    passed by a running session; None otherwise."""
    quiz = cfg.get("quiz")
    if not quiz or s.status != "running" or (s.quiz or {}).get("outcome"):
        return None
    done = quiz_attempts(s)
    return {
        "attempt": len(done) + 1,
        "attempts": quiz["attempts"],
        "questions": [{"id": q["id"], "text": q["text"], "options": q["options"]} for q in quiz["questions"]],
        "wrong": done[-1].get("wrong", []) if done else [],
    }


def quiz_problems(cfg: dict[str, Any], answers: dict[str, int]) -> list[str]:
    """Why ``answers`` is not an answer to every question of the quiz (empty when it is)."""
    qs = {q["id"]: q for q in cfg["quiz"]["questions"]}
    missing, unknown = [k for k in qs if k not in answers], sorted(set(answers) - set(qs))
    problems = [f"answer every question: missing {missing}, unknown {unknown}"] if missing or unknown else []
    bad = {k: v for k, v in answers.items() if k in qs and not 0 <= v < len(qs[k]["options"])}
    if bad:
        problems.append(f"answers must be option indices of their question, got {bad}")
    return problems


def answer_quiz(db: DBSession, s: Session, cfg: dict[str, Any], attempt: int, answers: dict[str, int]) -> tuple[list[str], bool]:
    """Take attempt ``attempt`` at the quiz of session ``s`` (locked): (the ids of the questions
    it got wrong, whether it repeats a stored attempt).  The last failed attempt settles the
    outcome (and, with ``on_fail: end``, screens the session out).  Commits."""
    done = quiz_attempts(s)
    if attempt <= len(done):  # a repeat of a stored attempt (a retry after a lost answer)
        db.rollback()
        if done[attempt - 1]["answers"] != answers:
            raise Conflict(f"attempt {attempt} is already answered, with other answers")
        return done[attempt - 1]["wrong"], True
    due = quiz_due(s, cfg)
    if due is None or attempt != due["attempt"]:
        db.rollback()
        raise Conflict("no quiz attempt is due" if due is None else f"the attempt due is {due['attempt']}")
    problems = quiz_problems(cfg, answers)
    if problems:
        db.rollback()
        raise NotAllowed("; ".join(problems))
    quiz = cfg["quiz"]
    wrong = [q["id"] for q in quiz["questions"] if answers[q["id"]] != q["answer"]]
    record = dict(s.quiz or {"attempts": [], "outcome": None})
    record["attempts"] = [*done, {"answers": answers, "wrong": wrong, "at": iso(utcnow())}]
    if not wrong:
        record["outcome"] = "passed"
    elif len(record["attempts"]) >= quiz["attempts"]:
        record["outcome"] = "failed"
        if quiz["on_fail"] == "end":
            s.status = SCREENED
            s.ended_at = utcnow()
    s.quiz = record
    s.updated_at = utcnow()
    db.commit()
    return wrong, False


def check_passed(item: dict[str, Any], value: float) -> bool | None:
    """Whether an answer to an attention-check item is the point it instructs (None: not a check)."""
    return None if item.get("check") is None else float(value) == float(item["check"])


def _asked_after(s: Session, when: str, n: int) -> bool:
    """Whether a self-report or questionnaire asked ``when`` ("trial", "block", "end") is asked
    after trial ``n`` (never after a practice trial)."""
    trials = s.plan["trials"]
    if when == "none" or not 1 <= n <= len(trials) or trials[n - 1].get("practice"):
        return False
    if when == "block":
        return n == len(trials) or trials[n]["block"] != trials[n - 1]["block"]
    if when == "end":
        return n == len(trials)
    return True


def report_due(db: DBSession, s: Session, cfg: dict[str, Any]) -> int | None:
    """The trial after which a self-report is still expected, or None."""
    mode = cfg.get("self_report", "none")
    n = s.trials_done
    if not _asked_after(s, mode, n):
        return None
    if db.scalar(select(Report.id).where(Report.session_id == s.id, Report.after_trial == n)):
        return None
    return n


def add_report(db: DBSession, s: Session, cfg: dict[str, Any], after_trial: int, value: float) -> tuple[Report, bool]:
    mode = cfg.get("self_report", "none")
    if mode == "none":
        raise Conflict("this study takes no trust self-reports")
    stored = select(Report).where(Report.session_id == s.id, Report.after_trial == after_trial)
    old = db.scalar(stored)
    if old is not None:
        if abs(old.value - value) < 1e-12:
            return old, True
        raise Conflict(f"a self-report after trial {after_trial} is already stored (value {old.value:g})")
    if not 1 <= after_trial <= s.trials_done:
        raise Conflict(f"after_trial must be a committed trial (1..{s.trials_done}), got {after_trial}")
    if not _asked_after(s, mode, after_trial):
        raise Conflict(f"no self-report is asked after trial {after_trial} (self_report: {mode!r})")
    block = s.plan["trials"][after_trial - 1]["block"]
    rep = Report(session_id=s.id, after_trial=after_trial, block=block, scope=mode, value=value)
    db.add(rep)
    if try_commit(db):
        return rep, False
    old = db.scalar(stored)  # stored by a concurrent request meanwhile
    if old is None:
        raise Conflict(f"the self-report after trial {after_trial} could not be stored; try again")
    return old, True


def questionnaire_due(db: DBSession, s: Session, cfg: dict[str, Any]) -> dict[str, Any] | None:
    """The first of the study's questionnaires still to be answered after the last committed
    trial (with ``after_trial``), or None."""
    n = s.trials_done
    for q in cfg.get("questionnaires") or ():
        if _asked_after(s, q["when"], n) and not db.scalar(
            select(Answer.id).where(Answer.session_id == s.id, Answer.questionnaire == q["name"], Answer.after_trial == n)
        ):
            return {**q, "after_trial": n}
    return None


def still_due(db: DBSession, s: Session, cfg: dict[str, Any]) -> tuple[int | None, dict[str, Any] | None]:
    """What the participant must answer before going on: the trial a self-report is still expected
    after (:func:`report_due`), and, when none is, the questionnaire still to answer (:func:`questionnaire_due`)."""
    due = report_due(db, s, cfg)
    return due, questionnaire_due(db, s, cfg) if due is None else None


def ended(db: DBSession, s: Session, cfg: dict[str, Any], due: tuple[int | None, Any] | None = None) -> bool:
    """Whether the session is over: every trial committed and nothing left to answer (``due``: what
    :func:`still_due` gave, when already known)."""
    if s.status == SCREENED:
        return True
    return s.status == "done" and (still_due(db, s, cfg) if due is None else due) == (None, None)


def answer_problems(q: dict[str, Any], answers: dict[str, float]) -> list[str]:
    """Why ``answers`` is not a complete answer to questionnaire ``q`` (empty when it is): every
    item answered, no other, each with a whole point of the scale."""
    ids = [i["id"] for i in q["items"]]
    problems = []
    missing, unknown = [i for i in ids if i not in answers], sorted(set(answers) - set(ids))
    if missing or unknown:
        problems.append(f"answer every item of {q['name']!r}: missing {missing}, unknown {unknown}")
    lo, hi = q["scale"]["min"], q["scale"]["max"]
    bad = {k: v for k, v in answers.items() if k in ids and not (lo <= v <= hi and float(v).is_integer())}
    if bad:
        problems.append(f"answers must be whole points of the scale {lo}..{hi}, got {bad}")
    return problems


def add_answers(
    db: DBSession, s: Session, cfg: dict[str, Any], name: str, after_trial: int, answers: dict[str, float]
) -> tuple[list[Answer], bool]:
    """Store a questionnaire's answers (every item, each a point of its scale); returns
    (answers, duplicate).  A repeat of stored answers is a duplicate; different ones are refused."""
    q = next((q for q in cfg.get("questionnaires") or () if q["name"] == name), None)
    if q is None:
        raise NotFound(f"this study has no questionnaire {name!r}")
    problems = answer_problems(q, answers)
    if problems:
        raise NotAllowed("; ".join(problems))
    ids = [i["id"] for i in q["items"]]
    old = db.scalars(
        select(Answer).where(Answer.session_id == s.id, Answer.questionnaire == name, Answer.after_trial == after_trial)
    ).all()
    if old:
        if {a.item: a.value for a in old} == {k: float(v) for k, v in answers.items()}:
            return list(old), True
        raise Conflict(f"{name!r} after trial {after_trial} is already answered, with other answers")
    if not 1 <= after_trial <= s.trials_done or not _asked_after(s, q["when"], after_trial):
        raise Conflict(f"{name!r} is not asked after trial {after_trial}")
    block = s.plan["trials"][after_trial - 1]["block"]
    rows = [
        Answer(
            session_id=s.id,
            questionnaire=name,
            when=q["when"],
            after_trial=after_trial,
            block=block,
            item=i,
            value=float(answers[i]),
        )
        for i in ids
    ]
    db.add_all(rows)
    if not try_commit(db):
        raise Conflict(f"{name!r} after trial {after_trial} was answered concurrently; fetch the state")
    return rows, False
