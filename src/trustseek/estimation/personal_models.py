"""Per-person models (the result of :func:`~.personal.personalize`): one model per participant, the
strengths that shrank them, and their files."""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..model.core import TrustModel
from ..model.files import planning_refusal
from ..model.jsonfile import json_safe
from .spec import FitError


@dataclass
class PersonalModels:
    """One trust model per participant (in the order of ``participants``, the study's values)."""

    participants: list[Any]
    models: list[TrustModel]  # general models for a centre with a study's named inputs
    centre: list[str]
    strength: dict[str, float]
    at_bound: dict[str, bool]
    method: dict[str, str]  # how each table's s was chosen
    estimate: str  # "held-out", "variational" or "given"
    score: float  # the criterion at the chosen strengths (held-out log-likelihood, or variational bound)
    score_centre: float  # the same at s = S_MAX in every table (the centre)
    loglik: np.ndarray
    centre_loglik: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    trials: np.ndarray
    warnings: list[str] = field(default_factory=list)

    def arrays(self) -> dict[str, Any]:
        """The models stacked as the arrays of a population of simulated supervisors
        (``Supervisors(**arrays)``: participant i is row i); trust models only."""
        first = self.models[0]
        if first.general:
            raise FitError([planning_refusal(first.used_inputs)])
        return {
            "trust_levels": first.trust_levels,
            "complexities": first.complexities,
            "initial": np.stack([m.initial for m in self.models]),
            "emission": np.stack([m.emission for m in self.models]),
            "transition": np.stack([m.transition for m in self.models]),
            "index": np.arange(len(self.models), dtype=np.int64),
        }

    def frame(self) -> pd.DataFrame:
        """One row per participant: the centre, trials, log-likelihood under the centre and own model."""
        return pd.DataFrame(
            {
                "participant": self.participants,
                "centre": self.centre,
                "trials": self.trials,
                "loglik_centre": self.centre_loglik,
                "loglik_personal": self.loglik,
                "iterations": self.iterations,
                "converged": self.converged,
            }
        )

    def file_names(self) -> list[str]:
        """A file name per participant: the participant value made safe, made unique if needed."""
        out: list[str] = []
        seen: set[str] = set()
        for i, p in enumerate(self.participants):
            base = re.sub(r"[^A-Za-z0-9._-]+", "_", str(p)).strip("._") or f"participant{i + 1}"
            name = base
            while name.lower() in seen:
                name = f"{base}-{i + 1}"
            seen.add(name.lower())
            out.append(f"{name}.json")
        return out

    def summary(self) -> dict[str, Any]:
        """The strengths, how they were chosen and the criterion (as ``strength.json`` holds them)."""
        return {k: getattr(self, k) for k in ("strength", "at_bound", "method", "estimate", "score", "score_centre", "warnings")}

    def save(self, folder: str | Path) -> None:
        """``<participant>.json`` per participant, ``participants.csv`` (with the file of each) and
        ``strength.json``, into ``folder`` (created)."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        names = self.file_names()
        for name, m in zip(names, self.models, strict=True):
            m.save(folder / name)
        table = self.frame()
        table.insert(1, "file", names)
        table.to_csv(folder / "participants.csv", index=False)
        (folder / "strength.json").write_text(
            json.dumps(json_safe(self.summary()), indent=2) + "\n",
            encoding="utf-8",
        )
