"""Study configuration (``docs/experiments.md``): its request bodies and validation, policy
resolution and per-participant plans.  A block with ``"schedule": "policy"`` runs a ``schedule``
policy, which picks before each trial which kind of item comes next, among the next ``window``
items of a queue shuffled per participant or among all remaining ones (``docs/scheduling.md``).
Policies are resolved once, at creation, into the core's policy JSON stored with the study, so
a study keeps behaving identically whatever the code later computes.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal, TypeVar

import numpy as np
from pydantic import Field, model_validator

from ..errors import TrustseekError
from ..model.core import TrustModel
from ..model.jsonfile import ModelError
from ..model.presets import MODEL_PRESETS, TASK_PRESETS
from ..model.task import Task
from ..policies.scheduling import SCHEDULE
from ..solvers import policy_from_spec
from .cache import StudyCaches
from .schemas import PRESETS_NAMED, Body, check_preset

_Spec = TypeVar("_Spec", Task, TrustModel)
_T = TypeVar("_T")

MAX_TRIALS_PER_BLOCK = 1000
MAX_GRID = 20001  # the largest belief grid a study may ask the server to solve
MAX_SCHEDULE_VALUES = 2_000_000  # the largest schedule policy (Q values) a study may ask the server to solve
#: a block's schedule when its policy picks the items
BY_POLICY = "policy"


class ConfigError(TrustseekError, ValueError):
    """A study or deploy configuration is invalid; ``problems`` lists every reason."""


class Schedule(Body):
    counts: dict[str, int] | None = Field(None, description="Trials per complexity, shuffled per participant.")
    trials: list[str] | None = Field(None, description="A fixed list of complexities, in order.")

    @model_validator(mode="after")
    def _one(self):
        problems = []  # every problem at once
        if (self.counts is None) == (self.trials is None):
            problems.append("a schedule needs exactly one of 'counts' or 'trials'")
        if self.counts is not None and any(v < 0 for v in self.counts.values()):
            problems.append(f"counts must be non-negative, got {self.counts}")
        n = sum(self.counts.values()) if self.counts is not None else len(self.trials or [])
        if not 1 <= n <= MAX_TRIALS_PER_BLOCK:
            problems.append(f"a block needs between 1 and {MAX_TRIALS_PER_BLOCK} trials, got {n}")
        if problems:
            raise ValueError("; ".join(problems))
        return self


class BlockIn(Body):
    name: str | None = Field(None, max_length=100)
    policy: dict[str, Any] = Field(..., description="A policy spec ({'kind': ...}) or a full policy JSON.")
    schedule: Schedule | Literal["policy"] = Field(
        ..., description="The items: counts or a fixed list, or 'policy' (a schedule policy picks each next item)."
    )


class PracticeIn(Body):
    """Practice trials before the first block: logged (``practice`` true), left out of the
    analysis export, scored nowhere, and without effect on the trust belief.  The robot asks
    (the participant teleoperates) in the practice trials ``asks`` (numbers from 1; by default
    the last one), and follows ``policy`` in the others."""

    trials: list[str] = Field(..., min_length=1, max_length=50, description="The practice trials' complexities, in order.")
    policy: dict[str, Any] = Field(default_factory=lambda: {"kind": "never-ask"}, description="The robot's policy in practice.")
    asks: list[int] | None = Field(
        None, max_length=50, description="Practice trials (from 1) in which the robot asks; default: the last."
    )

    @model_validator(mode="after")
    def _asks(self):
        bad = [k for k in self.asks or () if not 1 <= k <= len(self.trials)]
        if bad:
            raise ValueError(f"practice.asks names trials {bad}; the practice has trials 1..{len(self.trials)}")
        return self


class ScaleIn(Body):
    min: int = Field(1, ge=-1000, le=1000)
    max: int = Field(7, ge=-1000, le=1000)
    anchors: list[str] = Field(default_factory=list, max_length=2, description="Labels of the two ends.")

    @model_validator(mode="after")
    def _range(self):
        if not 1 <= self.max - self.min <= 100:
            raise ValueError(f"a scale needs between 2 and 101 points, got {self.min}..{self.max}")
        return self


class _Asked(Body):
    # what a questionnaire's item and a quiz's question share
    id: str = Field(..., min_length=1, max_length=100, pattern=r"^[A-Za-z0-9_.-]+$")
    text: str = Field(..., min_length=1, max_length=1000)


class ItemIn(_Asked):
    reverse: bool = False
    check: int | None = Field(None, description="An attention check: the point of the scale the item instructs.")


class QuizQuestionIn(_Asked):
    options: list[str] = Field(..., min_length=2, max_length=10)
    answer: int = Field(..., ge=0, description="The index of the right option (from 0).")

    @model_validator(mode="after")
    def _answer(self):
        if self.answer >= len(self.options):
            raise ValueError(f"answer {self.answer} is not an option of {self.id!r} (0..{len(self.options) - 1})")
        return self


class QuizIn(Body):
    """A comprehension quiz after the instructions: every question right to go on, within
    ``attempts`` attempts; then ``on_fail``: ``end`` (the session ends, with ``fail_code`` as the
    panel's code when given) or ``continue`` (the session goes on, the failure recorded)."""

    questions: list[QuizQuestionIn] = Field(..., min_length=1, max_length=20)
    attempts: int = Field(2, ge=1, le=10)
    on_fail: Literal["end", "continue"] = "end"
    fail_code: str | None = Field(None, min_length=1, max_length=100)

    @model_validator(mode="after")
    def _unique(self):
        if len({q.id for q in self.questions}) != len(self.questions):
            raise ValueError("quiz question ids must be unique")
        return self


class QuestionnaireIn(Body):
    """A questionnaire asked after every trial, after every block or at the end; either its
    items and scale, or ``template`` (a shipped questionnaire: ``questionnaire_templates()``)."""

    name: str | None = Field(None, min_length=1, max_length=100, pattern=r"^[A-Za-z0-9_.-]+$")
    when: Literal["trial", "block", "end"] = "end"
    template: str | None = None
    title: str | None = Field(None, max_length=1000)
    items: list[ItemIn] | None = Field(None, min_length=1, max_length=100)
    scale: ScaleIn | None = None

    @model_validator(mode="after")
    def _one(self):
        if (self.template is None) == (self.items is None):
            raise ValueError("a questionnaire needs exactly one of 'template' or 'items'")
        if self.items is not None and len({i.id for i in self.items}) != len(self.items):
            raise ValueError("questionnaire item ids must be unique")
        return self


class PanelIn(Body):
    """An online panel (Prolific and the like): the completion code and the redirect shown at the
    end, and the query parameters of the participant link that carry the panel's ids."""

    completion_code: str = Field(..., min_length=1, max_length=100)
    redirect_url: str | None = Field(None, max_length=2000, pattern=r"^https?://")
    id_params: list[str] = Field(default_factory=lambda: ["PROLIFIC_PID", "STUDY_ID", "SESSION_ID"], max_length=10)


class StudyIn(Body):
    name: str = Field(..., min_length=1, max_length=200)
    task: str | dict[str, Any] = "paper"
    model: str | dict[str, Any] = "paper"
    blocks: list[BlockIn] = Field(..., min_length=1, max_length=20)
    counterbalance: Literal["none", "rotate", "random"] = "none"
    self_report: Literal["none", "trial", "block"] = "none"
    animation_speed: float = Field(1.0, gt=0.05, le=50.0)
    # the participant's views: "3d" (WebGL; the 2-D scene where the browser has none) or "2d"
    scene: Literal["3d", "2d"] = "3d"
    seed: int = Field(0, ge=0, lt=2**31)
    consent_text: str | None = Field(None, max_length=20000)
    instructions: str | None = Field(None, max_length=20000)
    practice: PracticeIn | None = None
    questionnaires: list[QuestionnaireIn] = Field(default_factory=list, max_length=20)
    panel: PanelIn | None = None
    quota: int | None = Field(None, ge=1, le=100_000, description="Participants the study link takes; then it closes.")
    quiz: QuizIn | None = None
    _presets = PRESETS_NAMED


def _from_spec(field: str, spec: str | dict, presets: dict[str, Callable[[], _Spec]], cls: type[_Spec]) -> _Spec:
    """A preset by name or the JSON object of a ``field`` (``task`` or ``model``), or a
    ``ConfigError`` that says what is wrong."""
    try:
        return presets[check_preset(spec, field)]() if isinstance(spec, str) else cls.from_dict(spec, field)
    except ModelError as exc:
        raise ConfigError(exc.lines()) from None
    except ValueError as exc:  # not a preset
        raise ConfigError([str(exc)]) from None


def complexity_problems(model: TrustModel, task: Task) -> list[str]:
    """Why ``model`` cannot run with ``task`` (empty when it can): their complexities differ."""
    if tuple(model.complexities) == tuple(task.complexities):
        return []
    return [f"the model's complexities {list(model.complexities)} differ from the task's {list(task.complexities)}"]


def load_task_spec(spec: str | dict) -> Task:
    return _from_spec("task", spec, TASK_PRESETS, Task)


def load_model_spec(spec: str | dict) -> TrustModel:
    return _from_spec("model", spec, MODEL_PRESETS, TrustModel)


def resolve_policy(
    spec: dict[str, Any], model: TrustModel, task: Task, where: str = "policy", caches: StudyCaches | None = None
) -> dict[str, Any]:
    """A policy spec (``trustseek.solvers.registry``) to the core's policy JSON, solving the POMDP
    for ``trust-aware`` (remembered in the application's ``caches``: many sessions open with
    the same model, task and spec)."""
    key = None if "format" in spec or caches is None else json.dumps([model.to_dict(), task.to_dict(), spec], sort_keys=True)
    if key is not None and caches is not None:
        found = caches.resolved.get(key) or caches.schedules.get(key)
        if found is not None:
            return found
    try:
        policy = policy_from_spec(spec, model, task, where, max_grid=MAX_GRID, max_values=MAX_SCHEDULE_VALUES).to_dict()
    except TrustseekError as exc:
        raise ConfigError(exc.lines()) from None
    if key is not None and caches is not None:
        (caches.schedules if policy["kind"] == SCHEDULE else caches.resolved).put(key, policy)
    return policy


def build_study_config(study: StudyIn, caches: StudyCaches | None = None) -> dict[str, Any]:
    """Validate every part of a study and return the stored configuration."""
    problems: list[str] = []

    def checked(make: Callable[..., _T], *args: Any) -> _T | None:
        """``make(*args)``, or None with its problems noted."""
        try:
            return make(*args)
        except ConfigError as exc:
            problems.extend(exc.problems)
            return None

    task, model = checked(load_task_spec, study.task), checked(load_model_spec, study.model)
    # the other parts are checked against what is known, so that every problem is named at once
    known = task or model
    unknown = [] if known is None else unknown_complexities(study, tuple(known.complexities))
    if task is not None and model is not None:
        problems += complexity_problems(model, task)
    if problems or task is None or model is None:
        raise ConfigError(problems + unknown)
    problems += unknown
    blocks = [checked(resolve_block, b, i, model, task, caches) for i, b in enumerate(study.blocks)]
    practice = None if study.practice is None else checked(resolve_practice, study.practice, model, task, caches)
    questionnaires = [checked(resolve_questionnaire, q, f"questionnaires[{i}]") for i, q in enumerate(study.questionnaires)]
    names = [q["name"] for q in questionnaires if q is not None]
    if len(set(names)) != len(names):
        problems.append(f"questionnaire names must be unique, got {names}")
    if problems:
        raise ConfigError(problems)
    cfg = study.model_dump(exclude={"blocks", "task", "model", "practice", "questionnaires"})
    cfg.update(task=task.to_dict(), model=model.to_dict(), blocks=blocks, practice=practice, questionnaires=questionnaires)
    return cfg


def resolve_block(b: BlockIn, i: int, model: TrustModel, task: Task, caches: StudyCaches | None) -> dict[str, Any]:
    """Block ``i`` as stored with the study: its name, resolved policy and schedule."""
    where, s = f"blocks[{i}]", b.schedule
    pol = resolve_policy(b.policy, model, task, f"{where}.policy", caches)
    if not isinstance(s, Schedule):
        schedule = chosen_schedule(pol, where)
    elif pol["kind"] == SCHEDULE:
        raise ConfigError([f'{where}: a schedule policy picks the items: give the block "schedule": "{BY_POLICY}"'])
    else:
        schedule = {"counts": s.counts} if s.counts is not None else {"trials": s.trials}
    return {"name": b.name or f"block {i + 1}", "policy": pol, "schedule": schedule}


def resolve_practice(p: PracticeIn, model: TrustModel, task: Task, caches: StudyCaches | None) -> dict[str, Any]:
    """The practice as stored with the study: its trials, resolved policy and the trials the robot asks in."""
    policy = resolve_policy(p.policy, model, task, "practice.policy", caches)
    if policy["kind"] == SCHEDULE:
        raise ConfigError(["practice.policy: practice trials are a fixed list; a schedule policy runs in a block"])
    asks = p.asks if p.asks is not None else [len(p.trials)]
    return {"trials": list(p.trials), "policy": policy, "asks": sorted(set(asks))}


def unknown_complexities(study: StudyIn, complexities: tuple[str, ...]) -> list[str]:
    """The blocks' and the practice's complexities that are not among ``complexities``."""
    named = [(f"blocks[{i}].schedule", b.schedule) for i, b in enumerate(study.blocks) if isinstance(b.schedule, Schedule)]
    lists = [(w, list(s.counts) if s.counts is not None else list(s.trials or [])) for w, s in named]
    lists += [] if study.practice is None else [("practice.trials", study.practice.trials)]
    problems = []
    for where, names in lists:
        bad = sorted({c for c in names if c not in complexities})
        if bad:
            problems.append(f"{where} names unknown complexities {bad}; expected {list(complexities)}")
    return problems


def more_problems(body: Any, errors: list[dict[str, Any]]) -> list[str]:
    """The problems of a study body beyond those its fields' validation found (``errors``):
    the body without its refused top-level fields (their defaults instead) is checked as a study
    is, so that a study with several problems is refused naming them all."""
    if not isinstance(body, dict):
        return []
    refused = {e["loc"][1] for e in errors if len(e.get("loc", ())) > 1 and e["loc"][0] == "body"}
    rest = {k: v for k, v in body.items() if k not in refused}
    if "blocks" in refused or "name" in refused:  # required: something to check the others against
        rest.setdefault("name", "x")
        rest.setdefault("blocks", [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}}])
    try:
        build_study_config(StudyIn.model_validate(rest))
    except ConfigError as exc:
        return exc.problems
    except ValueError:  # refused by the fields' validation after all
        pass
    return []


QUESTIONNAIRES = Path(__file__).resolve().parent / "questionnaires"


def chosen_schedule(policy: dict[str, Any], where: str) -> dict[str, Any]:
    """The stored schedule of a block whose ``schedule`` policy picks the items: its counts (by
    complexity) and window."""
    if policy.get("kind") != SCHEDULE:
        kind = policy.get("kind")
        raise ConfigError(
            [f'{where}: "schedule": "{BY_POLICY}" needs a {SCHEDULE} policy (it picks the items), got a {kind} policy']
        )
    counts = dict(zip(policy["complexities"], policy["counts"], strict=True))
    n = sum(counts.values())
    if not 1 <= n <= MAX_TRIALS_PER_BLOCK:
        raise ConfigError([f"{where}: a block needs between 1 and {MAX_TRIALS_PER_BLOCK} trials, got {n}"])
    return {"by": BY_POLICY, "counts": counts, "window": policy.get("window")}


def questionnaire_templates() -> dict[str, dict[str, Any]]:
    """The shipped questionnaires by template name (``server/questionnaires/*.json``)."""
    return {p.stem: json.loads(p.read_text()) for p in sorted(QUESTIONNAIRES.glob("*.json"))}


def resolve_questionnaire(q: QuestionnaireIn, where: str) -> dict[str, Any]:
    """A questionnaire as stored with the study: name, when, title, scale and items."""
    if q.template is not None:
        templates = questionnaire_templates()
        if q.template not in templates:
            raise ConfigError([f"{where}.template: unknown template {q.template!r}; templates: {sorted(templates)}"])
        t = templates[q.template]
        out = {"name": q.name or t["name"], "when": q.when, "title": q.title or t["title"], "source": t.get("source")}
        out.update(scale=t["scale"], items=t["items"])
        return out
    assert q.items is not None
    scale = q.scale or ScaleIn(min=1, max=7)
    off = [i.id for i in q.items if i.check is not None and not scale.min <= i.check <= scale.max]
    if off:
        raise ConfigError([f"{where}.items {off}: an attention check must be a point of the scale {scale.min}..{scale.max}"])
    return {
        "name": q.name or f"questionnaire-{where.rsplit('[', 1)[-1].rstrip(']')}",
        "when": q.when,
        "title": q.title or "",
        "source": None,
        "scale": scale.model_dump(),
        "items": [i.model_dump() for i in q.items],
    }


def practice_count(cfg: dict[str, Any]) -> int:
    """The practice trials of a study (the first trials of every session)."""
    return len((cfg.get("practice") or {}).get("trials", []))


def block_order(cfg: dict[str, Any], index: int, rng: np.random.Generator) -> list[int]:
    """The block order of the ``index``-th participant (0-based) under the study's counterbalancing."""
    n = len(cfg["blocks"])
    base = list(range(n))
    if cfg["counterbalance"] == "rotate":
        k = index % n
        return base[k:] + base[:k]
    if cfg["counterbalance"] == "random":
        return [int(x) for x in rng.permutation(n)]
    return base


def participant_plan(cfg: dict[str, Any], index: int, seed: int) -> dict[str, Any]:
    """Block order and each block's complexity sequence, drawn once per participant."""
    rng = np.random.default_rng([cfg["seed"], seed])
    order = block_order(cfg, index, rng)
    trials: list[dict[str, Any]] = []
    queues: dict[str, list[str]] = {}
    for b in order:
        sched = cfg["blocks"][b]["schedule"]
        if "trials" in sched:
            trials.extend({"block": b, "complexity": c} for c in sched["trials"])
            continue
        items = [c for c, k in sched["counts"].items() for _ in range(k)]
        if sched.get("by") != BY_POLICY:
            trials.extend({"block": b, "complexity": items[i]} for i in rng.permutation(len(items)))
            continue
        # the policy picks each item when it is served, when it sees a window from the front of a queue
        if sched.get("window") is not None:
            queues[str(b)] = [items[i] for i in rng.permutation(len(items))]
        trials.extend({"block": b, "complexity": None} for _ in items)
    practice = cfg.get("practice")
    if practice:
        # the practice block's index follows the study's blocks
        asks = practice.get("asks") or ()
        trials[:0] = [
            {"block": len(cfg["blocks"]), "complexity": c, "practice": True, **({"action": "ask"} if k + 1 in asks else {})}
            for k, c in enumerate(practice["trials"])
        ]
    plan: dict[str, Any] = {"block_order": order, "trials": trials}
    if queues:
        plan["queues"] = queues
    return plan


def block_items(
    cfg: dict[str, Any], plan: dict[str, Any], block: int, picks: list[str]
) -> tuple[dict[str, int], dict[str, int] | None]:
    """(remaining, visible) items per complexity of a block whose policy picks the items, after
    the complexities ``picks`` (in order); visible is None when the robot sees every item.
    Each pick takes the first item of its complexity among the visible ones (the front of the
    participant's queue), and the next queued item comes into view."""
    sched = cfg["blocks"][block]["schedule"]
    remaining = dict(sched["counts"])
    for c in picks:
        remaining[c] -= 1
    window = sched.get("window")
    if window is None:
        return remaining, None
    queue = list(plan["queues"][str(block)])
    for c in picks:
        del queue[queue.index(c, 0, window)]
    visible = dict.fromkeys(remaining, 0)
    for c in queue[:window]:
        visible[c] += 1
    return remaining, visible
