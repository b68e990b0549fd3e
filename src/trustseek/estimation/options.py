"""How a fit searches: one set of options shared by every fit, selection and bootstrap."""

from __future__ import annotations

import operator
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

from ..seeds import seed_sequence

if TYPE_CHECKING:
    import numpy as np

__all__ = ["DEFAULTS", "FINISH_SWITCH", "SERIAL", "FitOptions", "RunSettings", "counting"]

FINISH_SWITCH = 1e-5  # EM hands over to the quasi-Newton finish at this relative change (or the fit's tol if looser)


@dataclass(frozen=True)
class FitOptions:
    """The search of an EM fit, apart from the model it fits.

    ``restarts`` random starts (the best run is kept; ``None`` where a function chooses by the
    model's free parameters, as :func:`~.selection.select_levels`), drawn from ``seed`` (an
    integer; :func:`~.iohmm.fit_iohmm` and :func:`~.mixture.fit_mixture` also take a
    :class:`numpy.random.SeedSequence`, the fits that derive several seeds from it do not); each
    run stops when the relative change of its objective is below ``tol``, or after ``max_iter``
    E-steps; ``n_jobs`` threads share the E-steps (processes for a bootstrap; ``None``: all
    cores).  Results do not depend on ``n_jobs``."""

    restarts: int | None = 10
    seed: int | np.random.SeedSequence = 0
    tol: float = 1e-8
    max_iter: int = 1000
    n_jobs: int | None = None

    @property
    def starts(self) -> int:
        """The number of random starts (``restarts``, which must be set)."""
        if self.restarts is None:
            raise ValueError("restarts is None: this fit needs a number of random starts")
        return self.restarts

    @property
    def seed_number(self) -> int:
        """``seed`` as an integer (the fits that derive several seeds from it take no SeedSequence)."""
        return operator.index(cast("int", self.seed))

    @property
    def seed_sequence(self) -> np.random.SeedSequence:
        """``seed`` as a :class:`numpy.random.SeedSequence` of the fit's own (:func:`~trustseek.seeds.seed_sequence`:
        the same options give the same fit however often they are used)."""
        return seed_sequence(self.seed)

    def run(self, quasi_newton: bool = True, accelerate: bool = True) -> RunSettings:
        """How each start of a fit with these options runs (:class:`RunSettings`)."""
        return RunSettings(
            tol=self.tol,
            max_iter=self.max_iter,
            em_tol=max(self.tol, FINISH_SWITCH) if quasi_newton else self.tol,
            quasi_newton=quasi_newton,
            accelerate=accelerate,
            threads=max(1, int(self.n_jobs or os.cpu_count() or 1)),
        )


@dataclass(frozen=True)
class RunSettings:
    """How each start of one fit runs (:meth:`FitOptions.run`), passed whole to :func:`~.em.converge` and
    :func:`~.compiled_run.run_starts`: to a stationary point (one more EM step gains at most ``tol``,
    relative) or ``max_iter`` E-steps; EM to ``em_tol`` before the finish (with ``quasi_newton``);
    ``accelerate``: SQUAREM; ``threads``: shared by the starts and E-steps (no number depends on them)."""

    tol: float = 1e-8
    max_iter: int = 1000
    em_tol: float = 1e-8
    quasi_newton: bool = True
    accelerate: bool = True
    threads: int = 1


#: the options' defaults: 10 restarts from seed 0, to a relative tolerance of 1e-8, on all cores
DEFAULTS = FitOptions()
#: the options' defaults on one thread (the default of the fits that run inside others)
SERIAL = FitOptions(n_jobs=1)


def counting(progress: Callable[[int, int], None] | None, total: int) -> Callable[..., None]:
    """A callback (of any arguments: a restart's, a replicate's) that counts its calls and reports
    ``progress(done, total)`` after each."""
    done = 0

    def tick(*_: Any) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    return tick
