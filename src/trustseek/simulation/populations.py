"""Populations of simulated supervisors: who the participants are.

Everyone shares one model (:meth:`Supervisors.pooled`), each participant draws their own
rows around a pooled model (:meth:`Supervisors.dirichlet`; the paper's Remark 1 on
conservative individuals), participants take models from a list
(:meth:`Supervisors.from_models`), or each participant is one of a mixture's supervisor types
(:meth:`Supervisors.from_mixture`; ``index`` is then the type).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..errors import TrustseekError
from ..model.core import TrustModel, trust_model
from ..model.mixture import TypeMixture


class SimulationError(TrustseekError, ValueError):
    """Inconsistent simulation inputs (shapes, names, counts)."""


def check_participants(n: int) -> None:
    """Refuse a number of participants that is not a positive integer."""
    if int(n) != n or n < 1:
        raise SimulationError([f"the number of participants must be a positive integer, got {n!r}"])


MAX_TRIALS = 100_000_000  # simulated trials in one schedule (about 1.3 GB of trials)


def check_size(n: int, trials: int, options: str = "") -> None:
    """Refuse ``n`` participants x ``trials`` trials above :data:`MAX_TRIALS` (``options``: what the
    caller's user sets them with, named in the message)."""
    if n * trials > MAX_TRIALS:
        fewer = f"simulate fewer ({options})" if options else "simulate fewer"
        raise SimulationError(
            [f"{n:,} participants x {trials:,} trials each is more than {MAX_TRIALS:,} simulated trials: {fewer}"]
        )


@dataclass(frozen=True, eq=False)
class Supervisors:
    """Per-participant supervisor parameters.

    ``initial[p]``, ``emission[p]`` and ``transition[p]`` hold the arrays of a
    :class:`TrustModel` for parameter row ``p``; participant ``i`` uses row ``index[i]``.
    """

    trust_levels: tuple[str, ...]
    complexities: tuple[str, ...]
    initial: np.ndarray  # (P, K)
    emission: np.ndarray  # (P, N, 2, K, 2)
    transition: np.ndarray  # (P, N, 2, 2, K, K)
    index: np.ndarray  # (n,)

    @property
    def n(self) -> int:
        return len(self.index)

    @property
    def n_rows(self) -> int:
        return self.initial.shape[0]

    @property
    def n_trust(self) -> int:
        return len(self.trust_levels)

    @classmethod
    def pooled(cls, model: TrustModel, n: int) -> Supervisors:
        """``n`` participants who all behave like ``model``."""
        check_participants(n)
        return cls(
            model.trust_levels,
            model.complexities,
            model.initial[None],
            model.emission[None],
            model.transition[None],
            np.zeros(n, dtype=np.int64),
        )

    @classmethod
    def from_models(cls, models: Sequence[TrustModel], n: int | None = None) -> Supervisors:
        """Participant ``i`` behaves like ``models[i % len(models)]`` (``n`` defaults to ``len(models)``)."""
        if not models:
            raise SimulationError(["from_models needs at least one model"])
        first = models[0]
        for j, m in enumerate(models):
            if m.trust_levels != first.trust_levels or m.complexities != first.complexities:
                raise SimulationError(
                    [
                        f"model {j} has trust levels {list(m.trust_levels)} and complexities {list(m.complexities)}; "
                        f"expected {list(first.trust_levels)} and {list(first.complexities)} like model 0"
                    ]
                )
        n = len(models) if n is None else n
        check_participants(n)
        return cls(
            first.trust_levels,
            first.complexities,
            np.stack([m.initial for m in models]),
            np.stack([m.emission for m in models]),
            np.stack([m.transition for m in models]),
            np.arange(n, dtype=np.int64) % len(models),
        )

    @classmethod
    def from_mixture(
        cls, mixture: TypeMixture, n: int, rng: np.random.Generator | int | None = None, draw: bool = False
    ) -> Supervisors:
        """``n`` participants of a population of supervisor types: participant ``i`` has type
        ``index[i]`` (an index into ``mixture.names``).  By default the shares are the mixture's
        weights exactly (largest remainder, then shuffled with ``rng``); ``draw=True`` draws each
        participant's type independently."""
        check_participants(n)
        g = np.random.default_rng(rng)
        types = mixture.sample_types(n, g) if draw else g.permutation(mixture.counts(n))
        return replace(cls.from_models(mixture.models), index=types.astype(np.int64))

    @classmethod
    def dirichlet(
        cls,
        model: TrustModel,
        n: int,
        concentration: float,
        rng: np.random.Generator | int | None = 0,
        pseudo: float = 0.0,
    ) -> Supervisors:
        """``n`` individuals drawn around a pooled ``model``: every probability row ``r`` of the
        model (initial trust, each emission row, each transition row) becomes a draw from
        Dirichlet(concentration * r + pseudo).  Larger ``concentration`` means a more homogeneous
        population; cells with zero weight (``r = 0`` and ``pseudo = 0``) stay zero."""
        check_participants(n)
        if not (np.isfinite(concentration) and concentration > 0):
            raise SimulationError([f"concentration (--concentration) must be a finite positive number, got {concentration!r}"])
        if not (np.isfinite(pseudo) and pseudo >= 0):
            raise SimulationError([f"pseudo (--pseudo) must be a finite number 0 or more, got {pseudo!r}"])
        rng = np.random.default_rng(rng)

        def draw(rows: np.ndarray) -> np.ndarray:
            alpha = concentration * rows + pseudo
            g = rng.gamma(np.broadcast_to(alpha, (n,) + alpha.shape))
            s = g.sum(axis=-1, keepdims=True)
            # a row whose draws all underflow to zero keeps the pooled row
            return np.where(s > 0, g / np.where(s > 0, s, 1.0), rows)

        return cls(
            model.trust_levels,
            model.complexities,
            draw(model.initial),
            draw(model.emission),
            draw(model.transition),
            np.arange(n, dtype=np.int64),
        )

    def model_of(self, participant: int) -> TrustModel:
        """The TrustModel of participant ``participant`` (0-based)."""
        p = int(self.index[participant])
        return trust_model(self.trust_levels, self.complexities, self.initial[p], self.emission[p], self.transition[p])

    def take(self, idx: np.ndarray) -> Supervisors:
        """The sub-population of participants ``idx`` (0-based indices)."""
        return replace(self, index=self.index[np.asarray(idx)])
