"""What a discrete input-output hidden Markov model (IOHMM) is made of: its structure and its parameters.

The model (Bengio & Frasconi 1996, as used in Section II of the paper) has K hidden
levels, one discrete output column and discrete input columns:

* ``initial[k]``            P(S_1 = k)
* ``emission[u, k, y]``     P(y_t = y | S_t = k, emission inputs of trial t = u)
* ``transition[u, k, j]``   P(S_{t+1} = j | S_t = k, transition inputs of trial t = u)

``u`` is the combination of the named input columns (C-order over the columns as
listed in the spec).  The transition from trial t to t+1 uses the inputs recorded
in row t, so a variable known only after the trial (the paper's experience E_{t+1})
is simply a column of row t.

A spec may name a second output, ``rating`` (a self-reported rating with ordinal levels
``rating_levels``), emitted by the hidden level alone: P(y, r | S = k, u) = P(y | k, u) P(r | k),
either factor 1 where that output is missing.  The E-step then sees one joint output
(:mod:`.ratings`); ``emission`` holds the joint table.

Structure (:class:`IOHMMSpec`): fixed rows (e.g. P(intervene | ask) = 1), rows tied
across input combinations, Dirichlet pseudo-counts ``prior`` (MAP), and the rule
that names the levels.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Self

import numpy as np

from ..errors import TrustseekError

#: the largest Dirichlet pseudo-count a fit takes (--prior, personalize's --strength): one this
#: large already fixes every row at the prior's; near 1e308 the log-prior overflowed and the fit
#: failed with "the initial values give the data probability zero"
MAX_PSEUDOCOUNT = 1e12
#: the tables of a model (:class:`Params`' arrays)
TABLES = ("initial", "emission", "transition")


class FitError(TrustseekError, ValueError):
    """The data and the model structure do not fit together (e.g. an event a fixed cell forbids)."""


@dataclass(frozen=True)
class Fixed:
    """Rows fixed to given values for every hidden level.

    ``where`` selects input combinations by column value (``{}`` = all).  ``probs``
    maps output categories to probabilities (emissions) or is ``"identity"``
    (transitions: the level does not change).
    """

    where: Mapping[str, str]
    probs: Mapping[str, float] | str

    def to_dict(self) -> dict[str, Any]:
        return {"where": dict(self.where), "probs": self.probs if isinstance(self.probs, str) else dict(self.probs)}


@dataclass(frozen=True)
class IOHMMSpec:
    """Structure of a discrete IOHMM: levels, output, inputs and constraints.

    ``order_by = (where, category)`` names the levels: they are sorted by the emission
    probability of ``category`` in the input combinations ``where``, lowest first.
    """

    levels: tuple[str, ...]
    output: str
    output_categories: tuple[str, ...]
    emission_inputs: tuple[str, ...] = ()
    transition_inputs: tuple[str, ...] = ()
    categories: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    fixed_emissions: tuple[Fixed, ...] = ()
    fixed_transitions: tuple[Fixed, ...] = ()
    tied_emissions: tuple[tuple[Mapping[str, str], ...], ...] = ()
    tied_transitions: tuple[tuple[Mapping[str, str], ...], ...] = ()
    order_by: tuple[Mapping[str, str], str] | None = None
    prior: float = 0.0
    rating: str | None = None  # the column of a second output emitted by the level alone (None: none)
    rating_levels: tuple[str, ...] = ()  # its ordinal levels, lowest first

    @property
    def n_levels(self) -> int:
        return len(self.levels)

    @property
    def n_outputs(self) -> int:
        return len(self.output_categories)

    @property
    def n_ratings(self) -> int:
        return len(self.rating_levels) if self.rating is not None else 0

    @property
    def n_emitted(self) -> int:
        """Categories of the output the E-step sees: the output's, or with a rating the joint
        (output or missing) x (rating or missing) categories (see :mod:`.ratings`)."""
        if self.rating is None:
            return self.n_outputs
        return (self.n_outputs + 1) * (self.n_ratings + 1)

    def n_combinations(self, inputs: Sequence[str]) -> int:
        """Number of value combinations of ``inputs`` (1 for no inputs)."""
        return int(np.prod([len(self.categories[c]) for c in inputs])) if inputs else 1

    def problems(self) -> list[str]:
        """Everything wrong with the spec itself (empty when it is consistent)."""
        p: list[str] = []
        if len(self.levels) < 1 or len(set(self.levels)) != len(self.levels):
            p.append(f"levels must be distinct names, got {list(self.levels)}")
        if len(self.output_categories) < 2:
            p.append(f"the output {self.output!r} needs at least 2 categories")
        for col in (*self.emission_inputs, *self.transition_inputs):
            if col not in self.categories or len(self.categories[col]) < 1:
                p.append(f"input column {col!r} has no categories")
        for name, cols in (("emission", self.emission_inputs), ("transition", self.transition_inputs)):
            if len(set(cols)) != len(cols):
                p.append(f"{name} inputs repeat a column: {list(cols)}")
            if self.output in cols:
                p.append(f"the output {self.output!r} cannot also be a {name} input")
        if self.rating is not None:
            if len(self.rating_levels) < 2 or len(set(self.rating_levels)) != len(self.rating_levels):
                p.append(f"the rating {self.rating!r} needs at least 2 distinct levels, got {list(self.rating_levels)}")
            if self.rating == self.output or self.rating in (*self.emission_inputs, *self.transition_inputs):
                p.append(f"the rating {self.rating!r} cannot also be the output or an input")
        if not 0 <= self.prior <= MAX_PSEUDOCOUNT:
            p.append(f"prior (--prior) must be a pseudo-count between 0 and {MAX_PSEUDOCOUNT:g}, got {self.prior!r}")
        return p

    def with_levels(self, levels: Sequence[str]) -> IOHMMSpec:
        return replace(self, levels=tuple(levels))

    def to_dict(self) -> dict[str, Any]:
        return {
            "levels": list(self.levels),
            "output": self.output,
            "output_categories": list(self.output_categories),
            "emission_inputs": list(self.emission_inputs),
            "transition_inputs": list(self.transition_inputs),
            "categories": {k: list(v) for k, v in self.categories.items()},
            "fixed_emissions": [f.to_dict() for f in self.fixed_emissions],
            "fixed_transitions": [f.to_dict() for f in self.fixed_transitions],
            "tied_emissions": [[dict(w) for w in g] for g in self.tied_emissions],
            "tied_transitions": [[dict(w) for w in g] for g in self.tied_transitions],
            "order_by": None if self.order_by is None else {"where": dict(self.order_by[0]), "category": self.order_by[1]},
            "prior": self.prior,
            **({"rating": self.rating, "rating_levels": list(self.rating_levels)} if self.rating is not None else {}),
        }


@dataclass
class Params:
    """IOHMM parameters: ``initial`` (K,), ``emission`` (U_e, K, M), ``transition`` (U_t, K, K).

    R parameter sets handled together (independent EM runs) carry a leading axis R on
    every array; :meth:`stack` and :meth:`take` convert between the two forms.
    """

    initial: np.ndarray
    emission: np.ndarray
    transition: np.ndarray
    OWN: ClassVar[int] = 1  # the trailing axes of ``initial`` that belong to one set (a mixture's: 2)

    @property
    def batched(self) -> bool:
        """True when the arrays carry a leading axis of parameter sets."""
        return self.initial.ndim == self.OWN + 1

    @classmethod
    def stack(cls, sets: Sequence[Params]) -> Self:
        """R single parameter sets as one with a leading axis R."""
        return cls(
            np.stack([p.initial for p in sets]), np.stack([p.emission for p in sets]), np.stack([p.transition for p in sets])
        )

    def as_batch(self) -> Self:
        """A single parameter set as a batch of one (views, no copies)."""
        return type(self)(self.initial[None], self.emission[None], self.transition[None])

    def take(self, r: int) -> Self:
        """Parameter set ``r`` of a batch (a copy)."""
        return type(self)(self.initial[r].copy(), self.emission[r].copy(), self.transition[r].copy())

    def where(self, mask: np.ndarray, other: Params) -> Self:
        """Per parameter set of a batch: this one where ``mask`` (R,) holds, else ``other``."""
        pairs = ((self.initial, other.initial), (self.emission, other.emission), (self.transition, other.transition))
        return type(self)(*(np.where(mask.reshape(-1, *[1] * (a.ndim - 1)), a, b) for a, b in pairs))

    def copy(self) -> Self:
        return type(self)(self.initial.copy(), self.emission.copy(), self.transition.copy())

    def vector(self) -> np.ndarray:
        """All cells in one vector (one row per parameter set of a batch)."""
        lead = self.initial.shape[: -self.OWN]
        return np.concatenate([a.reshape(*lead, -1) for a in (self.initial, self.emission, self.transition)], axis=-1)

    def from_vector(self, x: np.ndarray) -> Self:
        """Parameters shaped like these, with cells from ``x`` (the inverse of :meth:`vector`)."""
        lead = x.ndim - 1
        a = int(np.prod(self.initial.shape[lead:]))
        b = int(np.prod(self.emission.shape[lead:]))
        return type(self)(
            x[..., :a].reshape(self.initial.shape).copy(),
            x[..., a : a + b].reshape(self.emission.shape).copy(),
            x[..., a + b :].reshape(self.transition.shape).copy(),
        )

    def permuted(self, perm: np.ndarray) -> Params:
        """The same model with the levels renumbered: new level i is old level ``perm[i]``."""
        return Params(self.initial[perm], self.emission[:, perm], self.transition[:, perm][:, :, perm])
