"""Built-in presets.  ``paper`` holds the numbers of Section V of the paper as printed, plus
one assumption the paper does not state.

The paper prints its estimates rounded to two decimals, so these are not its exact values:
the threshold of the optimal policy moves with that rounding (the printed values give
0.7812 where the paper reports ≈ 0.75; ``trustseek sensitivity`` gives the range the
printed precision allows, :mod:`trustseek.solvers.sensitivity`).

**Assumption:** P(C = high) = 0.5 in :func:`paper_task`.  The paper names the probability
(p_{C^H}, Section III) but never gives its value; its data collection had 30 high-complexity
trials in 71 (30/71 ≈ 0.42), and its evaluation blocks 17 in 34 (0.5).  The reproduction
report shows the threshold with 30/71 as well.

Cells the paper never observes are set to the identity (trust does not change)
and listed in :data:`PAPER_UNOBSERVED_CELLS`:

* ``transition[C=low, a=ask, E=reliable]``: asking in low complexity is always
  recorded as ``faulty``, so a ``reliable`` experience never follows it.
* ``transition[C=high, a=ask, E=faulty]``: asking in high complexity is always
  recorded as ``reliable``.

Emissions of ``ask`` are P(intervene) = 1 for every trust and complexity: when
asked, the human always teleoperates (Fig. 4a).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..vocab import ASK, AUTONOMOUS, FAULTY, LEVELS, RELIABLE
from .core import TrustModel, trust_model
from .jsonfile import ModelError
from .mixture import TypeMixture
from .task import Rewards, Task

PAPER_UNOBSERVED_CELLS = (
    "transition[C=low, a=ask, E=reliable]",
    "transition[C=high, a=ask, E=faulty]",
)

LOW, HIGH = 0, 1


def _supervisor(initial: list[float], emission: list, transition: dict, notes: str) -> TrustModel:
    """A two-level supervisor over low and high complexity: ``emission[c]`` the rows P(o | T) of
    acting autonomously, [intervene, rely] for T = low then high (asked, the human always
    teleoperates: Fig. 4a); ``transition[(c, a, E')]`` the rows P(T' | T), T' = low then high,
    every cell not given the identity (trust does not change)."""
    em = np.zeros((2, 2, 2, 2))
    em[:, AUTONOMOUS] = emission
    em[:, ASK] = [[1.0, 0.0], [1.0, 0.0]]
    tr = np.zeros((2, 2, 2, 2, 2))
    tr[...] = np.eye(2)
    for cell, rows in transition.items():
        tr[cell] = rows
    return trust_model(LEVELS, LEVELS, np.array(initial), em, tr, notes)


def paper_model() -> TrustModel:
    """The supervisor model estimated in Section V (Figs. 4-6)."""
    emission = [
        [[0.02, 0.98], [0.00, 1.00]],  # Fig. 4b
        [[0.54, 0.46], [0.05, 0.95]],  # Fig. 4c
    ]
    transition = {  # Fig. 5a (low, autonomous, reliable) and 5c (low, ask, faulty): the identity
        (LOW, AUTONOMOUS, FAULTY): [[0.99, 0.01], [0.39, 0.61]],  # Fig. 5b
        (HIGH, AUTONOMOUS, RELIABLE): [[0.0, 1.0], [0.0, 1.0]],  # Fig. 6a
        (HIGH, AUTONOMOUS, FAULTY): [[0.70, 0.30], [1.00, 0.00]],  # Fig. 6b
        (HIGH, ASK, RELIABLE): [[0.56, 0.44], [0.06, 0.94]],  # Fig. 6c
    }
    notes = (
        "Section V of Mangalindan, Rovira & Srivastava, 'On trust-aware assistance-seeking in "
        "human-supervised autonomy'. Never-observed cells (identity): " + "; ".join(PAPER_UNOBSERVED_CELLS)
    )
    return _supervisor([0.0, 1.0], emission, transition, notes)


def conservative_model() -> TrustModel:
    """A conservative supervisor (the paper's Remark 1): not sure of the robot at the start,
    often intervenes in low complexity when trust is low, loses trust after any failure and
    repairs it slowly.  Same structure and fixed cells as :func:`paper_model`; the numbers are
    illustrative, not estimated from data."""
    emission = [[[0.35, 0.65], [0.02, 0.98]], [[0.85, 0.15], [0.10, 0.90]]]
    transition = {
        (LOW, AUTONOMOUS, RELIABLE): [[0.95, 0.05], [0.0, 1.0]],
        (LOW, AUTONOMOUS, FAULTY): [[1.0, 0.0], [0.70, 0.30]],
        (HIGH, AUTONOMOUS, RELIABLE): [[0.80, 0.20], [0.0, 1.0]],
        (HIGH, AUTONOMOUS, FAULTY): [[1.0, 0.0], [1.0, 0.0]],
        (HIGH, ASK, RELIABLE): [[0.85, 0.15], [0.15, 0.85]],
    }
    notes = (
        "A conservative supervisor (Remark 1 of the paper): intervenes in low complexity when trust is low, "
        "loses trust after failures and repairs it slowly. Illustrative numbers, not estimated."
    )
    return _supervisor([0.5, 0.5], emission, transition, notes)


def paper_conservative_mixture(conservative_share: float = 0.3) -> TypeMixture:
    """A population of the paper's supervisor and the conservative one (30 % by default)."""
    return TypeMixture(
        ("paper", "conservative"),
        np.array([1.0 - conservative_share, conservative_share]),
        (paper_model(), conservative_model()),
        notes="the paper's supervisor (Section V) and a conservative type (Remark 1)",
    )


def paper_task() -> Task:
    """The object-collection task of Sections III-V: rewards of eq. (1), gamma = 0.987,
    success probabilities 0.97 / 0.83 as printed; P(C = high) = 0.5 is an assumption (see
    the module docstring)."""
    return Task(
        complexities=("low", "high"),
        complexity_probs=np.array([0.5, 0.5]),
        success=np.array([0.97, 0.83]),
        ask_experience=(FAULTY, RELIABLE),
        rewards=Rewards(autonomous_success=2.0, ask=1.0, intervene=0.0, autonomous_failure=-3.0),
        discount=0.987,
    )


MODEL_PRESETS = {"paper": paper_model, "conservative": conservative_model}
TASK_PRESETS = {"paper": paper_task}
MIXTURE_PRESETS = {
    "paper": lambda: TypeMixture.single(paper_model(), "paper"),
    "conservative": lambda: TypeMixture.single(conservative_model(), "conservative"),
    "paper+conservative": paper_conservative_mixture,
}


def _resolve(spec: str | Path, presets: dict, loader, kind: str):
    s = str(spec)
    if s in presets:
        return presets[s]()
    p = Path(s)
    if p.suffix == "" and not p.exists():
        raise ModelError([f"unknown {kind} preset {s!r}; presets: {sorted(presets)}; or give a path to a JSON file"])
    return loader(p)


def load_model(spec: str | Path) -> TrustModel:
    """A trust model from a preset name (``paper``) or a JSON file path."""
    return _resolve(spec, MODEL_PRESETS, TrustModel.load, "model")


def load_mixture(spec: str | Path) -> TypeMixture:
    """Supervisor types from a preset name (``paper+conservative``; a model preset is one type) or a
    JSON file: a mixture, or a plain trust model read as one type."""
    return _resolve(spec, MIXTURE_PRESETS, TypeMixture.load, "mixture")


def load_task(spec: str | Path) -> Task:
    """A task from a preset name (``paper``) or a JSON file path."""
    return _resolve(spec, TASK_PRESETS, Task.load, "task")
