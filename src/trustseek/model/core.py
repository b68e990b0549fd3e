"""The supervisor model: one class, :class:`TrustModel`, an IOHMM of a hidden level (trust), one
output (the human action) and named discrete inputs, with an optional rating table.

The trust model the planner needs is this model configured with the paper's inputs
(:func:`trust_model`): emissions on complexity and the robot action, transitions on
complexity, the robot action and the experience.  A study may condition on anything it logs
instead (a between-subject condition, the aid's advice, an image's difficulty): the model then
keeps those inputs by name, each with its levels in their declared order (a general model,
``general``); planning (solve, simulate, the policies) refuses it, decoding, prediction and
validation take either.

The vocabulary and indices are :mod:`trustseek.vocab`'s.

Tables (``numpy.float64``), one axis per input in the order the table lists them, then the
level, then the output category (or the next level)::

    initial[t]                          P(T_1 = t)
    emission[*emission inputs, t, o]    P(o_t = o | T_t = t, the trial's emission inputs)
    transition[*transition inputs, t, t2]  P(T_{t+1} = t2 | T_t = t, the trial's transition inputs)
    rating.probs[t, r]                  P(self-reported rating = r | T_t = t) (optional table)

so that a trust model has ``emission[c, a, t, o]`` and ``transition[c, a, e, t, t2]``;
``emission_rows`` and ``transition_rows`` are the same tables by input combination ``u`` (C
order over the inputs, the first varying slowest).  The JSON formats (``trustseek.trust-model/1``
for a trust model, ``trustseek.iohmm/1`` for a general one) are in ``docs/formats.md`` and
:mod:`.files`; loading validates every cell and reports every problem at once through
:class:`~trustseek.model.jsonfile.ModelError`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from dataclasses import replace as _replace
from pathlib import Path
from typing import Any

import numpy as np

from ..vocab import INTERVENE
from .files import (
    PLANNING_INPUTS,
    SYMBOLS,
    model_fields,
    model_to_dict,
    planning_refusal,
    trust_fields,
)
from .jsonfile import (
    JsonFile,
    ModelError,
    build,
    check_names,
    check_row_array,
    complexity_index,
    load_json,
)
from .rating import RatingTable


@dataclass(frozen=True, eq=False)
class TrustModel(JsonFile):
    """An IOHMM of hidden trust with named inputs (see the module docstring).

    ``structure`` is None for a trust model (the paper's inputs, written as
    ``trustseek.trust-model/1``), and for a general model the fixed and tied rows, ``order_by``
    and ``prior`` it was fitted with (written as ``trustseek.iohmm/1``).  ``not_estimated``
    lists a trust model's rows no data ever estimated (e.g. every ask row of a model fitted
    from a study without asking): ``("emission", (c, a))`` or ``("transition", (c, a, e))``.
    """

    levels: tuple[str, ...]
    output: str
    output_categories: tuple[str, ...]
    inputs: Mapping[str, tuple[str, ...]]  # every input's levels, in their declared order
    emission_inputs: tuple[str, ...]
    transition_inputs: tuple[str, ...]
    initial: np.ndarray
    emission: np.ndarray
    transition: np.ndarray
    structure: Mapping[str, Any] | None = field(default_factory=dict)
    rating: RatingTable | None = None
    rating_column: str | None = None
    notes: str = ""
    not_estimated: tuple[tuple[str, tuple[int, ...]], ...] = ()

    def __post_init__(self) -> None:
        for name in ("levels", "output_categories", "emission_inputs", "transition_inputs"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        object.__setattr__(self, "inputs", {str(k): tuple(v) for k, v in self.inputs.items()})
        object.__setattr__(self, "structure", None if self.structure is None else dict(self.structure))
        object.__setattr__(
            self, "not_estimated", tuple(sorted({(str(t), tuple(int(i) for i in idx)) for t, idx in self.not_estimated}))
        )
        self._freeze_and_check("initial", "emission", "transition")

    # -- configuration -----------------------------------------------------
    @property
    def general(self) -> bool:
        """True for a general model (inputs a trust model does not have, or a fitted structure kept)."""
        return self.structure is not None

    @property
    def n_levels(self) -> int:
        return len(self.levels)

    def axes(self, inputs: Sequence[str]) -> tuple[int, ...]:
        return tuple(len(self.inputs[c]) for c in inputs)

    def n_combinations(self, inputs: Sequence[str]) -> int:
        return int(np.prod(self.axes(inputs))) if inputs else 1

    @property
    def used_inputs(self) -> tuple[str, ...]:
        """The inputs of either table, emission inputs first."""
        return tuple(dict.fromkeys((*self.emission_inputs, *self.transition_inputs)))

    @property
    def emission_rows(self) -> np.ndarray:
        """``emission`` by input combination: (U, K, M)."""
        return self.emission.reshape(self.n_combinations(self.emission_inputs), self.n_levels, -1)

    @property
    def transition_rows(self) -> np.ndarray:
        """``transition`` by input combination: (U, K, K)."""
        return self.transition.reshape(self.n_combinations(self.transition_inputs), self.n_levels, self.n_levels)

    def symbol(self, name: str) -> str:
        """How row names show an input (``C``, ``a``, ``E`` for a trust model) or the level (``T``)."""
        if self.general:
            return "level" if name == "level" else name
        return "T" if name == "level" else SYMBOLS[name]

    def combination(self, table: str, u: int) -> dict[str, str]:
        """The input levels of combination ``u`` of ``table`` (``emission`` or ``transition``)."""
        inputs = self.emission_inputs if table == "emission" else self.transition_inputs
        if not inputs:
            return {}
        idx = np.unravel_index(u, self.axes(inputs))
        return {c: self.inputs[c][int(i)] for c, i in zip(inputs, idx, strict=True)}

    def row_name(self, table: str, where: int | Sequence[int], k: int | None = None) -> str:
        """``emission[C=high, a=ask]``, ``transition[C=high, a=ask, E=reliable][T=low]`` or
        ``emission[advice=agree, difficulty=hard][level=low]``: the row at input combination
        ``where`` (its index ``u``, or one index per input) and level ``k``."""
        inputs = self.emission_inputs if table == "emission" else self.transition_inputs
        if isinstance(where, int | np.integer):
            u = int(where)
        else:
            u = int(np.ravel_multi_index(tuple(where), self.axes(inputs))) if inputs else 0
        named = ", ".join(f"{self.symbol(c)}={v}" for c, v in self.combination(table, u).items())
        s = f"{table}[{named}]" if named else table
        return s if k is None else f"{s}[{self.symbol('level')}={self.levels[k]}]"

    def problems(self) -> list[str]:
        """Every violation of the model's constraints, as human-readable lines."""
        if not self.general and not self.paper_inputs:
            return [f"a trust model has the paper's inputs ({', '.join(PLANNING_INPUTS)}); give a general model a structure"]
        p = self._name_problems()
        if p and self.general:
            return p
        K, M = self.n_levels, len(self.output_categories)
        shapes = {
            "initial": (K,),
            "emission": (*self.axes(self.emission_inputs), K, M),
            "transition": (*self.axes(self.transition_inputs), K, K),
        }
        p += [f"{n} has shape {getattr(self, n).shape}, expected {s}" for n, s in shapes.items() if getattr(self, n).shape != s]
        if p:
            return p
        check_row_array(self.initial[None, :], lambda i: "initial", p)
        for table in ("emission", "transition"):
            check_row_array(getattr(self, table), lambda i, t=table: self.row_name(t, i[:-1], i[-1]), p)
        return p + self._extras_problems()

    def _name_problems(self) -> list[str]:
        """The names: a trust model's trust levels and complexities (two or more each), a general
        model's levels, output categories, inputs and their levels."""
        p: list[str] = []
        if not self.general:
            check_names(list(self.levels), "trust_levels", p)
            check_names(list(self.inputs["complexity"]), "complexities", p)
            return p
        check_names(list(self.levels), "levels", p, minimum=1)
        check_names(list(self.output_categories), "output categories", p)
        for name, cols in (("emission_inputs", self.emission_inputs), ("transition_inputs", self.transition_inputs)):
            if len(set(cols)) != len(cols):
                p.append(f"{name} repeat an input: {list(cols)}")
            p += [f"{name}: {c!r} is not one of the inputs {list(self.inputs)}" for c in cols if c not in self.inputs]
        for c, lv in self.inputs.items():
            check_names(list(lv), f"input {c!r} levels", p, minimum=1)
        return p

    @property
    def paper_inputs(self) -> bool:
        """True when the inputs are the paper's (as a trust model has them: :func:`~.files.trust_fields`)."""
        paper = trust_fields(self.levels, self.inputs.get("complexity", ()))
        return all(getattr(self, k) == v for k, v in paper.items() if k != "structure")

    def _extras_problems(self) -> list[str]:
        p: list[str] = []
        if self.not_estimated and self.general:
            p.append("not_estimated marks rows of a trust model; a general model has none")
        row_shapes: dict[str, tuple[int, ...]] = {"emission": self.emission.shape[:-2], "transition": self.transition.shape[:-2]}
        for table, idx in self.not_estimated:
            rshape = row_shapes.get(table)
            if rshape is None or len(idx) != len(rshape) or any(not 0 <= i < n for i, n in zip(idx, rshape, strict=False)):
                p.append(f"not_estimated: {table}{list(idx)} is not a row of the model")
        if self.rating is not None:
            if not isinstance(self.rating, RatingTable):
                p.append(f"rating must be a RatingTable, got {type(self.rating).__name__}")
            else:
                p += self.rating.problems(self.levels)
        return p

    # -- what the planner names --------------------------------------------
    @property
    def trust_levels(self) -> tuple[str, ...]:
        return self.levels

    @property
    def complexities(self) -> tuple[str, ...]:
        """A trust model's complexities (a general model is refused: planning needs a trust model)."""
        if self.general:
            raise ModelError([planning_refusal(self.used_inputs)])
        return self.inputs["complexity"]

    n_trust = n_levels  # the planner's name

    @property
    def n_complexity(self) -> int:
        return len(self.complexities)

    def complexity_index(self, name: str) -> int:
        return complexity_index(self.complexities, name)

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

    # -- JSON (the two formats: .files) -------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return model_to_dict(self)

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None, general: bool = False) -> TrustModel:
        """A trust model from its JSON form; with ``general``, a general model file too (by its
        ``format``), which is otherwise refused (planning needs a trust model)."""
        fields = model_fields(d, source, general)
        return build([], source, lambda: cls(**fields))

    def replace(self, **changes: Any) -> TrustModel:
        """This model with ``changes`` (fields, or a trust model's ``trust_levels`` and ``complexities``)."""
        if "trust_levels" in changes:
            changes["levels"] = changes.pop("trust_levels")
        if "complexities" in changes:
            changes["inputs"] = {**self.inputs, "complexity": tuple(changes.pop("complexities"))}
        return _replace(self, **changes)


def trust_model(
    trust_levels: Sequence[str],
    complexities: Sequence[str],
    initial: Any,
    emission: Any,
    transition: Any,
    notes: str = "",
    not_estimated: Sequence[tuple[str, tuple[int, ...]]] = (),
    rating: RatingTable | None = None,
) -> TrustModel:
    """The trust model with the paper's inputs: ``emission[c, a, t, o]`` and
    ``transition[c, a, e, t, t2]`` over ``complexities``, the robot actions and the experiences."""
    return TrustModel(**trust_fields(trust_levels, complexities), initial=initial, emission=emission, transition=transition,
                      rating=rating, notes=notes, not_estimated=tuple(not_estimated))  # fmt: skip


def load_any_model(path: str | Path) -> TrustModel:
    """A trust model file (``trustseek.trust-model/1``, or no format) or a general model file
    (``trustseek.iohmm/1``), by its ``format``."""
    d, source = load_json(path)
    return TrustModel.from_dict(d, source, general=True)
