"""Request bodies (validated by pydantic; FastAPI answers 422 with every problem).

Types are strict (``true`` is not a number, ``1`` is not a boolean, ``"3"`` is not an integer)
and numbers finite (``NaN`` and ``Infinity``, which Python's JSON reader accepts, are refused);
every integer has an upper bound, so that nothing overflows a database column.
"""

from __future__ import annotations

import json
import math
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from ..model.presets import MODEL_PRESETS, TASK_PRESETS

#: the largest trial number the API accepts (a deploy session may run for a long time)
MAX_TRIAL = 10**7
#: the largest ``data`` of one UI event, as compact JSON
MAX_EVENT_DATA = 4096
#: UI events in one post
MAX_EVENTS_PER_POST = 5000


class Body(BaseModel):
    """A request body: strict types, finite numbers, no field beyond those declared."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


class ErrorOut(BaseModel):
    """The body of every refused request (4xx other than 422): ``detail`` is a sentence, or an
    object such as ``{"problems": [...]}`` listing every problem of a configuration."""

    detail: str | dict[str, Any] | list[Any]


def finite_json(value: Any, where: str = "data") -> Any:
    """``value`` if it holds no NaN or infinite number (at any depth), else ValueError."""
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{where} holds a non-finite number ({value!r}); numbers must be finite")
    if isinstance(value, dict):
        for k, v in value.items():
            finite_json(v, f"{where}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            finite_json(v, f"{where}[{i}]")
    return value


def page_made_id(max_length: int, description: str) -> Any:
    """An optional field holding an id that the participant's page makes (letters, digits, ``_`` and ``-``)."""
    return Field(None, min_length=1, max_length=max_length, pattern=r"^[A-Za-z0-9_-]+$", description=description)


class EventIn(Body):
    t: float | None = Field(None, description="Client time, ms since the Unix epoch.")
    type: str = Field(..., min_length=1, max_length=40)
    trial: int | None = Field(None, ge=1, le=MAX_TRIAL)
    page: str | None = page_made_id(
        32,
        "The page load that made the event: a random id the page makes when it opens (a reload or a second tab makes another).",
    )
    data: dict[str, Any] = Field(default_factory=dict)

    @field_validator("data")
    @classmethod
    def _finite(cls, v):
        finite_json(v)
        if len(json.dumps(v, separators=(",", ":"))) > MAX_EVENT_DATA:
            raise ValueError(f"an event's data must be at most {MAX_EVENT_DATA} characters of JSON")
        return v


class SessionsIn(Body):
    participants: list[str] | None = Field(None, max_length=1000, description="Participant ids; default P001, P002, ...")
    count: int = Field(1, ge=1, le=1000, description="How many sessions when participants is not given.")
    pilot: bool = Field(False, description="Pilot sessions: flagged, left out of the analysis export unless asked for.")


class StatusIn(Body):
    status: Literal["draft", "open", "paused", "closed"]


class ConsentIn(Body):
    agree: Literal[True]
    events: list[EventIn] = Field(default_factory=list, max_length=MAX_EVENTS_PER_POST)
    panel: dict[str, str] = Field(
        default_factory=dict, max_length=10, description="An online panel's ids from the link's query (PROLIFIC_PID, ...)."
    )

    @field_validator("panel")
    @classmethod
    def _short(cls, v):
        if any(not k or len(k) > 100 or len(x) > 200 for k, x in v.items()):
            raise ValueError("panel ids: names of at most 100 characters, values of at most 200")
        return v

    @field_validator("agree", mode="before")
    @classmethod
    def _true(cls, v):
        if v is not True:  # Literal[True] alone would take 1
            raise ValueError("agree must be true")
        return v


class TrialIn(Body):
    trial: int = Field(..., ge=1, le=100000)
    submission_id: str = Field(..., min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.:-]+$")
    human_action: Literal["intervene", "rely"]
    effort_ms: float | None = Field(None, ge=0, le=1e8)
    events: list[EventIn] = Field(default_factory=list, max_length=MAX_EVENTS_PER_POST)


class ReportIn(Body):
    after_trial: int = Field(..., ge=1, le=100000)
    value: float = Field(..., ge=0, le=100, description="Trust self-report on a 0-100 slider.")


class AnswersIn(Body):
    questionnaire: str = Field(..., min_length=1, max_length=100)
    after_trial: int = Field(..., ge=1, le=100000)
    answers: dict[str, float] = Field(..., min_length=1, max_length=100, description="Item id -> a point of the scale.")


class QuizAttemptIn(Body):
    attempt: int = Field(..., ge=1, le=10, description="The attempt's number, from 1 (a retry repeats it).")
    answers: dict[str, int] = Field(..., min_length=1, max_length=20, description="Question id -> option index.")


class EventsIn(Body):
    events: list[EventIn] = Field(..., min_length=1, max_length=MAX_EVENTS_PER_POST)
    batch: str | None = page_made_id(64, "A client-made id of this batch: the same batch posted again (a retry) is stored once.")


def check_preset(v: Any, field: str) -> Any:
    """A preset name must name a preset (a JSON object is checked when it is loaded)."""
    presets = TASK_PRESETS if field == "task" else MODEL_PRESETS
    if isinstance(v, str) and v not in presets:
        raise ValueError(f"unknown {field} preset {v!r}; presets: {sorted(presets)}, or give the JSON object")
    return v


#: the validator of a body's ``task`` and ``model``: a name must name a preset
PRESETS_NAMED = field_validator("task", "model")(lambda cls, v, info: check_preset(v, info.field_name))


class DeployIn(Body):
    label: str = Field("robot", min_length=1, max_length=200)
    task: str | dict[str, Any] = "paper"
    model: str | dict[str, Any] = "paper"
    policy: dict[str, Any] = Field(default_factory=lambda: {"kind": "trust-aware"})
    seed: int = Field(0, ge=0, lt=2**31)
    _presets = PRESETS_NAMED


class DecideIn(Body):
    """A trial's complexity (the item is imposed), or, for a ``schedule`` policy, the items that
    remain (and those visible, when the policy sees a window) so that the policy picks the item."""

    trial: int = Field(..., ge=1, le=MAX_TRIAL)
    complexity: str | None = Field(None, min_length=1, max_length=32)
    remaining: dict[str, int] | None = None
    visible: dict[str, int] | None = None


class ObserveIn(Body):
    trial: int = Field(..., ge=1, le=MAX_TRIAL)
    human_action: Literal["intervene", "rely"] | None = None
    outcome: Literal["success", "failure", "collision", "dropped", "teleoperated"] | None = None
