"""A self-reported trust rating as a second emission of the hidden trust: ``RatingTable``."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .jsonfile import check_names, check_row_array, freeze_arrays, get_key, nested, read_entry, same_fields, unknown_keys


@dataclass(frozen=True, eq=False)
class RatingTable:
    """A self-reported trust rating as a second emission of the hidden trust.

    ``levels`` are the rating's ordinal levels, lowest first (e.g. ``"1"`` .. ``"7"``, or
    labels); ``probs[t, r]`` is P(rating = levels[r] | trust level t), one free row per trust
    level.  The rating depends on the trust only (not on complexity or the robot action),
    and a trial without a rating contributes probability 1.
    """

    levels: tuple[str, ...]
    probs: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "levels", tuple(self.levels))
        freeze_arrays(self, "probs")

    @property
    def n_levels(self) -> int:
        return len(self.levels)

    def problems(self, trust_levels: Sequence[str]) -> list[str]:
        """Every violation of the table's constraints for a model with ``trust_levels``."""
        problems: list[str] = []
        check_names(list(self.levels), "rating levels", problems)
        shape = (len(trust_levels), len(self.levels))
        if self.probs.shape != shape:
            problems.append(
                f"rating probabilities have shape {self.probs.shape}, expected {shape} (trust levels x rating levels)"
            )
            return problems
        check_row_array(self.probs, lambda i: f"rating[T={trust_levels[i[0]]}]", problems)
        return problems

    def to_dict(self, trust_levels: Sequence[str]) -> dict[str, Any]:
        return {"levels": list(self.levels), "probs": nested(self.probs, [trust_levels, self.levels])}

    @classmethod
    def read(cls, obj: Any, trust_levels: Sequence[str], problems: list[str]) -> RatingTable | None:
        """The ``rating`` entry of a model file (``{"levels": [...], "probs": {T: {level: p}}}``);
        every problem is appended to ``problems``."""
        if not isinstance(obj, Mapping):
            problems.append(f"rating must be an object with 'levels' and 'probs', got {obj!r}")
            return None
        unknown_keys(obj, ["levels", "probs"], "rating", problems)
        levels = check_names(get_key(obj, "levels", "rating.levels", problems), "rating.levels", problems)
        raw = get_key(obj, "probs", "rating.probs", problems)
        if not levels or raw is None:
            return None
        probs = np.full((len(trust_levels), len(levels)), np.nan)
        unknown_keys(raw, trust_levels, "rating.probs", problems)
        for t, name in enumerate(trust_levels):
            row = read_entry(raw, name, f"rating[T={name}]", levels, problems)
            if row is not None:
                probs[t] = row
        return cls(tuple(levels), probs)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RatingTable):
            return NotImplemented
        return same_fields(self, other)
