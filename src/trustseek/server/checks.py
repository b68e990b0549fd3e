"""Checks that researchers are expected to run: the comprehension quiz after the instructions
and attention-check items in questionnaires.

The quiz is every question right within the allowed attempts; each attempt is kept with the
session (its answers and the questions it got wrong).  After the last failed attempt the
study's ``on_fail`` decides: ``end`` screens the session out (it ends; the panel's
``fail_code``, if any, is shown instead of the completion code) or ``continue`` (the session
goes on, the failure recorded).  An attention-check item names the point of its scale that it
instructs; the export says whether each answer matched it.
"""

from __future__ import annotations

from typing import Any

from .orm import Session, iso, utcnow

#: a session's status once a failed quiz has ended it
SCREENED = "screened"


def quiz_due(s: Session, cfg: dict[str, Any]) -> dict[str, Any] | None:
    """The quiz as the participant's page shows it (no answers), while it is still to be
    passed by a running session; None otherwise."""
    quiz = cfg.get("quiz")
    if not quiz or s.status != "running" or (s.quiz or {}).get("outcome"):
        return None
    done = len((s.quiz or {}).get("attempts", []))
    return {
        "attempt": done + 1,
        "attempts": quiz["attempts"],
        "questions": [{"id": q["id"], "text": q["text"], "options": q["options"]} for q in quiz["questions"]],
        "wrong": (s.quiz or {}).get("attempts", [{}])[-1].get("wrong", []) if done else [],
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


def grade_quiz(s: Session, cfg: dict[str, Any], answers: dict[str, int]) -> list[str]:
    """Record an attempt; returns the ids of the questions it got wrong.  The last failed
    attempt settles the outcome (and, with ``on_fail: end``, screens the session out)."""
    quiz = cfg["quiz"]
    wrong = [q["id"] for q in quiz["questions"] if answers[q["id"]] != q["answer"]]
    record = dict(s.quiz or {"attempts": [], "outcome": None})
    record["attempts"] = [*record.get("attempts", []), {"answers": answers, "wrong": wrong, "at": iso(utcnow())}]
    if not wrong:
        record["outcome"] = "passed"
    elif len(record["attempts"]) >= quiz["attempts"]:
        record["outcome"] = "failed"
        if quiz["on_fail"] == "end":
            s.status = SCREENED
            s.ended_at = utcnow()
    s.quiz = record
    s.updated_at = utcnow()
    return wrong


def check_passed(item: dict[str, Any], value: float) -> bool | None:
    """Whether an answer to an attention-check item is the point it instructs (None: not a check)."""
    return None if item.get("check") is None else float(value) == float(item["check"])
