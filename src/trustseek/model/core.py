"""The supervisor model (`TrustModel`, with an optional `RatingTable`); the task is in ``task.py``.

Vocabulary (fixed everywhere in trustseek):

* robot action ``a``: ``autonomous`` / ``ask``            (index 0 / 1)
* human action ``o``: ``intervene`` / ``rely``            (index 0 / 1)
* experience ``E``:   ``faulty`` / ``reliable``           (index 0 / 1)
* trust ``T`` and complexity ``C`` have user-chosen, ordered names; the paper
  uses ``low`` / ``high`` for both.  Trust levels are ordered from lowest to
  highest, so for two levels the belief is P(trust = high) = b[-1].

Array layouts (all ``numpy.float64``):

* ``TrustModel.initial[t]``                      P(T_1 = t)
* ``TrustModel.emission[c, a, t, o]``             P(o_t = o | T_t = t, C_t = c, a_t = a)
* ``TrustModel.transition[c, a, e, t, t2]``       P(T_{t+1} = t2 | T_t = t, E_{t+1} = e, C_t = c, a_t = a)
* ``TrustModel.rating.probs[t, r]``               P(self-reported rating = r | T_t = t) (optional table)

JSON formats are documented in ``docs/formats.md``.  Loading validates every
cell and reports every problem at once through :class:`~trustseek.model.jsonfile.ModelError`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..vocab import ACTIONS, ASK, AUTONOMOUS, EXPERIENCES, FAULTY, HUMAN_ACTIONS, INTERVENE, RELIABLE, RELY
from .jsonfile import (
    JsonFile,
    ModelError,
    UnknownComplexityError,
    check_names,
    check_row_array,
    freeze_arrays,
    get_key,
    nested,
    raise_problems,
    read_row,
    read_table,
    unknown_keys,
)

__all__ = [  # the vocabulary is re-exported for convenience
    "ACTIONS",
    "ASK",
    "AUTONOMOUS",
    "EXPERIENCES",
    "FAULTY",
    "HUMAN_ACTIONS",
    "INTERVENE",
    "IOHMM_FORMAT",
    "MODEL_FORMAT",
    "PLANNING_INPUTS",
    "RELIABLE",
    "RELY",
    "RatingTable",
    "TrustModel",
    "planning_refusal",
]

MODEL_FORMAT = "trustseek.trust-model/1"
IOHMM_FORMAT = "trustseek.iohmm/1"  # a general model with named inputs (model/iohmm.py)
PLANNING_INPUTS = ("complexity", "robot_action", "experience")  # the inputs of a trust model, which planning needs


def planning_refusal(inputs: Sequence[str]) -> str:
    """The one line said where a trust model is needed and a general model (with ``inputs``) is given."""
    named = ", ".join(inputs) if inputs else "none"
    return (
        f"a general IOHMM model ({IOHMM_FORMAT}, inputs: {named}) is not a trust model: planning "
        f"(solve, simulate, policies) needs a trust model ({MODEL_FORMAT}) whose inputs are among "
        f"{', '.join(PLANNING_INPUTS)} (fit with --transitions-on/--emissions-on naming only those)"
    )


# --------------------------------------------------------------------------- TrustModel


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
        if not all(isinstance(n, str) and n for n in self.levels):
            problems.append(f"rating levels must be non-empty strings, got {list(self.levels)!r}")
        if len(set(self.levels)) != len(self.levels):
            problems.append(f"rating levels have duplicate names: {list(self.levels)}")
        if len(self.levels) < 2:
            problems.append(f"rating levels need at least 2 entries, got {len(self.levels)}")
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
            cell = get_key(raw, name, f"rating[T={name}]", problems)
            if cell is not None:
                row = read_row(cell, levels, f"rating[T={name}]", problems)
                if row is not None:
                    probs[t] = row
        return cls(tuple(levels), probs)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RatingTable):
            return NotImplemented
        return self.levels == other.levels and np.array_equal(self.probs, other.probs)


@dataclass(frozen=True, eq=False)
class TrustModel(JsonFile):
    """The supervisor: hidden trust, its dynamics, and how it drives the human action."""

    trust_levels: tuple[str, ...]
    complexities: tuple[str, ...]
    initial: np.ndarray
    emission: np.ndarray
    transition: np.ndarray
    notes: str = ""
    # rows no data ever estimated (e.g. every ask row of a model fitted from a study without
    # asking): ("emission", (c, a)) or ("transition", (c, a, e)); empty = all estimated
    not_estimated: tuple[tuple[str, tuple[int, ...]], ...] = ()
    # the optional second emission: a self-reported rating, P(rating | trust) (None: no ratings)
    rating: RatingTable | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "trust_levels", tuple(self.trust_levels))
        object.__setattr__(self, "complexities", tuple(self.complexities))
        object.__setattr__(
            self, "not_estimated", tuple(sorted({(str(t), tuple(int(i) for i in idx)) for t, idx in self.not_estimated}))
        )
        freeze_arrays(self, "initial", "emission", "transition")
        raise_problems(self)

    # -- shape -------------------------------------------------------------
    @property
    def n_trust(self) -> int:
        return len(self.trust_levels)

    @property
    def n_complexity(self) -> int:
        return len(self.complexities)

    def problems(self) -> list[str]:
        """Every violation of the model's constraints, as human-readable lines."""
        K, N = len(self.trust_levels), len(self.complexities)
        problems: list[str] = []
        for what, names in (("trust_levels", self.trust_levels), ("complexities", self.complexities)):
            if len(set(names)) != len(names):
                problems.append(f"{what} has duplicate names: {list(names)}")
            if len(names) < 2:
                problems.append(f"{what} needs at least 2 entries, got {len(names)}")
        shapes = {
            "initial": (K,),
            "emission": (N, 2, K, 2),
            "transition": (N, 2, 2, K, K),
        }
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                problems.append(f"{name} has shape {getattr(self, name).shape}, expected {shape}")
        if problems:
            return problems
        T, C = self.trust_levels, self.complexities
        check_row_array(self.initial[None, :], lambda idx: "initial", problems)
        check_row_array(
            self.emission,
            lambda i: f"emission[C={C[i[0]]}, a={ACTIONS[i[1]]}][T={T[i[2]]}]",
            problems,
        )
        check_row_array(
            self.transition,
            lambda i: f"transition[C={C[i[0]]}, a={ACTIONS[i[1]]}, E={EXPERIENCES[i[2]]}][T={T[i[3]]}]",
            problems,
        )
        row_shapes: dict[str, tuple[int, ...]] = {"emission": (N, 2), "transition": (N, 2, 2)}
        for table, idx in self.not_estimated:
            rshape = row_shapes.get(table)
            if rshape is None or len(idx) != len(rshape) or any(not 0 <= i < n for i, n in zip(idx, rshape, strict=False)):
                problems.append(f"not_estimated: {table}{list(idx)} is not a row of the model")
        if self.rating is not None:
            if not isinstance(self.rating, RatingTable):
                problems.append(f"rating must be a RatingTable, got {type(self.rating).__name__}")
            else:
                problems += self.rating.problems(T)
        return problems

    # -- convenience -------------------------------------------------------
    def trust_index(self, name: str) -> int:
        return self.trust_levels.index(name)

    def complexity_index(self, name: str) -> int:
        try:
            return self.complexities.index(name)
        except ValueError:
            raise UnknownComplexityError([f"unknown complexity {name!r}; expected one of {list(self.complexities)}"]) from None

    def row_name(self, table: str, idx: Sequence[int]) -> str:
        """``emission[C=high, a=ask]`` or ``transition[C=high, a=ask, E=reliable]``."""
        parts = [f"C={self.complexities[idx[0]]}", f"a={ACTIONS[idx[1]]}"]
        if table == "transition":
            parts.append(f"E={EXPERIENCES[idx[2]]}")
        return f"{table}[{', '.join(parts)}]"

    def not_estimated_rows(self) -> list[str]:
        """The rows no data estimated, by name (:meth:`row_name`)."""
        return [self.row_name(t, idx) for t, idx in self.not_estimated]

    def filled_from(self, other: TrustModel) -> TrustModel:
        """This model with every never-estimated row taken from ``other`` (same levels and complexities)."""
        if other.trust_levels != self.trust_levels or other.complexities != self.complexities:
            raise ModelError(
                [
                    f"cannot fill from a model with trust levels {list(other.trust_levels)} and complexities "
                    f"{list(other.complexities)}: this one has {list(self.trust_levels)} and {list(self.complexities)}"
                ]
            )
        em, tr = self.emission.copy(), self.transition.copy()
        for table, idx in self.not_estimated:
            (em if table == "emission" else tr)[idx] = (other.emission if table == "emission" else other.transition)[idx]
        still = tuple(r for r in self.not_estimated if r in other.not_estimated)
        return self.replace(emission=em, transition=tr, not_estimated=still)

    def p_intervene(self, belief: np.ndarray, c: int, a: int) -> float:
        """P(o = intervene | belief, C = c, a) for a belief vector over trust levels."""
        return float(np.asarray(belief) @ self.emission[c, a, :, INTERVENE])

    # -- JSON --------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        T, C = self.trust_levels, self.complexities
        return {
            "format": MODEL_FORMAT,
            "notes": self.notes,
            "trust_levels": list(T),
            "complexities": list(C),
            "initial": nested(self.initial, [T]),
            "emission": nested(self.emission, [C, ACTIONS, T, HUMAN_ACTIONS]),
            "transition": nested(self.transition, [C, ACTIONS, EXPERIENCES, T, T]),
            **({"not_estimated": [_row_dict(t, idx, C) for t, idx in self.not_estimated]} if self.not_estimated else {}),
            **({"rating": self.rating.to_dict(T)} if self.rating is not None else {}),
        }

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> TrustModel:
        problems: list[str] = []
        if not isinstance(d, Mapping):
            raise ModelError([f"a trust model must be a JSON object, got {type(d).__name__}"], source)
        fmt = d.get("format", MODEL_FORMAT)
        if fmt == IOHMM_FORMAT:
            inputs = [*d.get("emission_inputs", []), *d.get("transition_inputs", [])]
            raise ModelError([planning_refusal([str(c) for c in dict.fromkeys(inputs)])], source)
        if fmt != MODEL_FORMAT:
            problems.append(f"format is {fmt!r}, expected {MODEL_FORMAT!r}")
        unknown_keys(
            d,
            ["format", "notes", "trust_levels", "complexities", "initial", "emission", "transition", "not_estimated", "rating"],
            "model",
            problems,
        )
        T = check_names(get_key(d, "trust_levels", "trust_levels", problems), "trust_levels", problems)
        C = check_names(get_key(d, "complexities", "complexities", problems), "complexities", problems)
        if problems or not T or not C:
            raise ModelError(problems, source)
        K, N = len(T), len(C)
        initial = np.full(K, np.nan)
        emission = np.full((N, 2, K, 2), np.nan)
        transition = np.full((N, 2, 2, K, K), np.nan)

        init = get_key(d, "initial", "initial", problems)
        if init is not None:
            row = read_row(init, T, "initial", problems)
            if row is not None:
                initial[:] = row

        em = get_key(d, "emission", "emission", problems)
        if em is not None:
            read_table(em, "emission", [("C", C), ("a", ACTIONS)], ("T", T), HUMAN_ACTIONS, emission, problems)
        tr = get_key(d, "transition", "transition", problems)
        if tr is not None:
            read_table(tr, "transition", [("C", C), ("a", ACTIONS), ("E", EXPERIENCES)], ("T", T), T, transition, problems)
        notes = d.get("notes", "")
        if not isinstance(notes, str):
            problems.append(f"notes must be a string, got {notes!r}")
        not_estimated = _read_not_estimated(d.get("not_estimated", []), C, problems)
        rating = RatingTable.read(d["rating"], T, problems) if d.get("rating") is not None else None
        if problems:
            raise ModelError(problems, source)
        try:
            return cls(tuple(T), tuple(C), initial, emission, transition, notes=notes, not_estimated=not_estimated, rating=rating)
        except ModelError as exc:
            raise ModelError(exc.problems, source) from None

    def replace(self, **changes: Any) -> TrustModel:
        kw: dict[str, Any] = {
            "trust_levels": self.trust_levels,
            "complexities": self.complexities,
            "initial": self.initial,
            "emission": self.emission,
            "transition": self.transition,
            "notes": self.notes,
            "not_estimated": self.not_estimated,
            "rating": self.rating,
        }
        kw.update(changes)
        return TrustModel(**kw)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, TrustModel):
            return NotImplemented
        return (
            self.trust_levels == other.trust_levels
            and self.complexities == other.complexities
            and np.array_equal(self.initial, other.initial)
            and np.array_equal(self.emission, other.emission)
            and np.array_equal(self.transition, other.transition)
            and self.not_estimated == other.not_estimated
            and self.rating == other.rating
        )


def _row_dict(table: str, idx: tuple[int, ...], C: Sequence[str]) -> dict[str, str]:
    d = {"table": table, "C": C[idx[0]], "a": ACTIONS[idx[1]]}
    if table == "transition":
        d["E"] = EXPERIENCES[idx[2]]
    return d


def _read_not_estimated(raw: Any, C: Sequence[str], problems: list[str]) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """``not_estimated``: a list of rows ``{"table": "emission"|"transition", "C": .., "a": .., ["E": ..]}``."""
    if not isinstance(raw, list):
        problems.append(f"not_estimated must be a list of rows, got {raw!r}")
        return ()
    out = []
    for i, row in enumerate(raw):
        where = f"not_estimated[{i}]"
        if not isinstance(row, Mapping) or row.get("table") not in ("emission", "transition"):
            problems.append(f"{where}: expected {{'table': 'emission' or 'transition', 'C': ..., 'a': ...}}, got {row!r}")
            continue
        keys = [("C", list(C)), ("a", list(ACTIONS))] + ([("E", list(EXPERIENCES))] if row["table"] == "transition" else [])
        extra = set(row) - {"table", *(k for k, _ in keys)}
        if extra:
            problems.append(f"{where}: unknown keys {sorted(extra)}")
        idx = []
        for k, names in keys:
            if row.get(k) not in names:
                problems.append(f"{where}: {k} = {row.get(k)!r} is not one of {names}")
            else:
                idx.append(names.index(row[k]))
        if len(idx) == len(keys):
            out.append((str(row["table"]), tuple(idx)))
    return tuple(out)
