"""Request bodies (validated by pydantic; FastAPI answers 422 with every problem)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field


class EventIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    t: float | None = Field(None, description="Client time, ms since the Unix epoch.")
    type: str = Field(..., min_length=1, max_length=40)
    trial: int | None = Field(None, ge=1)
    data: dict[str, Any] = Field(default_factory=dict)


class SessionsIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    participants: list[str] | None = Field(None, max_length=1000, description="Participant ids; default P001, P002, ...")
    count: int = Field(1, ge=1, le=1000, description="How many sessions when participants is not given.")


class ConsentIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    agree: Literal[True]
    events: list[EventIn] = Field(default_factory=list, max_length=5000)


class TrialIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    trial: int = Field(..., ge=1, le=100000)
    submission_id: str = Field(..., min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.:-]+$")
    human_action: Literal["intervene", "rely"]
    effort_ms: float | None = Field(None, ge=0, le=1e8)
    events: list[EventIn] = Field(default_factory=list, max_length=5000)


class ReportIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    after_trial: int = Field(..., ge=1, le=100000)
    value: float = Field(..., ge=0, le=100, description="Trust self-report on a 0-100 slider.")


class EventsIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    events: list[EventIn] = Field(..., min_length=1, max_length=5000)


class DeployIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    label: str = Field("robot", min_length=1, max_length=200)
    task: str | dict[str, Any] = "paper"
    model: str | dict[str, Any] = "paper"
    policy: dict[str, Any] = Field(default_factory=lambda: {"kind": "trust-aware"})
    seed: int = Field(0, ge=0, lt=2**31)


class DecideIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    trial: int = Field(..., ge=1, le=10**7)
    complexity: str = Field(..., min_length=1, max_length=32)


class ObserveIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    trial: int = Field(..., ge=1, le=10**7)
    human_action: Literal["intervene", "rely"] | None = None
    outcome: Literal["success", "failure", "collision", "dropped", "teleoperated"] | None = None
