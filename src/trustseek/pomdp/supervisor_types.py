"""Planning for a supervisor whose type is unknown: the product of a type mixture.

A new person belongs to one of M supervisor types (a :class:`~trustseek.model.mixture.TypeMixture`),
which the robot does not know; the type never changes, trust moves as that type's model says.
The hidden state is then the pair (type m, trust k), and the belief is over both: the trials'
interventions and outcomes update it, so the robot learns whom it is working with.

This is itself a :class:`~trustseek.model.core.TrustModel` with M·K trust levels, built by
:func:`product_model`:

* level (m, k) has index ``m * K + k`` (type-major) and the name ``"<type>/<trust>"``,
  e.g. ``"paper/low"``, ``"paper/high"``, ``"conservative/low"``, ``"conservative/high"``;
* ``initial[(m, k)] = w_m · initial_m[k]``;
* ``emission[c, a, (m, k), o]`` = type m's emission at trust k;
* ``transition[c, a, e, (m, k), (m', k')]`` = type m's transition k → k' when m' = m, else 0
  (block-diagonal: the type is fixed).

So every solver, policy, belief filter and the simulator work on it unchanged:
``AssistancePOMDP(product_model(mixture), task)``.  The Bayes filter on the product belief is
each type's filter reweighted by how likely that type made the trial (the tests check it).
Product beliefs are rows of length M·K; :func:`type_marginal`, :func:`trust_marginal` and
:func:`trust_given_type` take them apart.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..errors import TrustseekError
from ..model.core import TrustModel, trust_model
from ..model.mixture import TypeMixture
from ..model.task import Task
from ..vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS, UNOBSERVED
from .belief import BayesUpdate
from .problem import AssistancePOMDP

if TYPE_CHECKING:  # the trial log is a data frame; planning without one loads no pandas
    import pandas as pd


#: joins a type's name and a trust level's name in the product model's level names
LEVEL_SEPARATOR = "/"


class TypeBeliefError(TrustseekError, ValueError):
    """A product belief or a trial history that does not fit the mixture."""


def level_name(type_name: str, trust_level: str) -> str:
    """The name of product level (type, trust): ``"paper/low"``."""
    return f"{type_name}{LEVEL_SEPARATOR}{trust_level}"


def product_model(mixture: TypeMixture | TrustModel) -> TrustModel:
    """The trust model over (type, trust) pairs of ``mixture`` (a plain model is one type, and
    its product is the model itself with its level names prefixed by the type's)."""
    if isinstance(mixture, TrustModel):
        mixture = TypeMixture.single(mixture)
    M, K = mixture.n_types, len(mixture.trust_levels)
    first = mixture.models[0]
    N = first.n_complexity
    initial = np.concatenate([w * m.initial for w, m in zip(mixture.weights, mixture.models, strict=True)])
    emission = np.concatenate([m.emission for m in mixture.models], axis=2)  # [c, a, (m, k), o]
    transition = np.zeros((N, 2, 2, M * K, M * K))
    for i, m in enumerate(mixture.models):
        transition[..., i * K : (i + 1) * K, i * K : (i + 1) * K] = m.transition
    not_estimated = tuple({row for m in mixture.models for row in m.not_estimated})
    return trust_model(
        trust_levels=tuple(level_name(n, t) for n in mixture.names for t in mixture.trust_levels),
        complexities=first.complexities,
        initial=initial,
        emission=emission,
        transition=transition,
        notes=f"(type, trust) product of {M} supervisor type(s) {list(mixture.names)}"
        + (f": {mixture.notes}" if mixture.notes else ""),
        not_estimated=not_estimated,
    )


def type_aware_problem(mixture: TypeMixture | TrustModel, task: Task) -> AssistancePOMDP:
    """The assistance POMDP over (type, trust): ``AssistancePOMDP(product_model(mixture), task)``."""
    return AssistancePOMDP(product_model(mixture), task)


def _grid(beliefs: np.ndarray | Sequence[float], n_types: int) -> np.ndarray:
    b = np.asarray(beliefs, dtype=float)
    if b.shape[-1] % n_types:
        raise TypeBeliefError([f"a belief of {b.shape[-1]} entries is not over {n_types} types x trust levels"])
    return b.reshape(*b.shape[:-1], n_types, b.shape[-1] // n_types)


def type_marginal(beliefs: np.ndarray | Sequence[float], n_types: int) -> np.ndarray:
    """P(type = m) of product beliefs (..., M·K): shape (..., M)."""
    return _grid(beliefs, n_types).sum(axis=-1)


def trust_marginal(beliefs: np.ndarray | Sequence[float], n_types: int) -> np.ndarray:
    """P(trust = k) of product beliefs (..., M·K), whatever the type: shape (..., K)."""
    return _grid(beliefs, n_types).sum(axis=-2)


def trust_given_type(beliefs: np.ndarray | Sequence[float], n_types: int) -> np.ndarray:
    """P(trust = k | type = m) of product beliefs (..., M·K): shape (..., M, K); a type of
    probability zero gets the uniform row."""
    g = _grid(beliefs, n_types)
    z = g.sum(axis=-1, keepdims=True)
    return np.where(z > 0, g / np.where(z > 0, z, 1.0), 1.0 / g.shape[-1])


def warm_start_belief(mixture: TypeMixture, type_belief: np.ndarray | Sequence[float] | None = None) -> np.ndarray:
    """The product belief at the start of a session: types distributed as ``type_belief`` (the
    mixture's weights when None), trust at each type's initial distribution."""
    w = mixture.weights if type_belief is None else np.asarray(type_belief, dtype=float).reshape(-1)
    if w.shape != (mixture.n_types,) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise TypeBeliefError([f"a type belief needs {mixture.n_types} non-negative numbers, not all zero; got {list(w)}"])
    w = w / w.sum()
    return np.concatenate([wm * m.initial for wm, m in zip(w, mixture.models, strict=True)])


def _codes(values: pd.Series, names: Sequence[str], column: str, missing_ok: bool = False) -> np.ndarray:
    """The index in ``names`` of each value (:data:`UNOBSERVED` where missing, if allowed)."""
    missing = values.isna().to_numpy()
    text = [str(v) for v in values.astype("object")]
    bad = {repr(s) for s, m in zip(text, missing, strict=True) if not m and s not in names}
    if not missing_ok and missing.any():
        bad.add("missing")
    if bad:
        raise TypeBeliefError([f"column {column!r}: {sorted(bad)} not among {list(names)}"])
    return np.array([UNOBSERVED if m else names.index(s) for s, m in zip(text, missing, strict=True)], dtype=np.int64)


def type_belief_from_log(
    mixture: TypeMixture,
    trials: pd.DataFrame,
    participant: str | None = None,
    session: str | None = None,
    prior: np.ndarray | Sequence[float] | None = None,
) -> np.ndarray:
    """The posterior over types of one person, given their earlier trials.

    ``trials`` has the canonical trial columns (``participant, trial, complexity, robot_action,
    human_action, experience``; a missing human action is not conditioned on).  ``participant``
    selects that person's rows (required when the log holds several).  Each value of the
    ``session`` column (when given) is a separate session that starts from each type's initial
    trust; without it the person's trials form one session, in ``trial`` order.  The trials are
    filtered through the product model from ``prior`` (default: the mixture's weights), and the
    type marginal of the last belief is returned: shape (M,).  A new session of this person
    starts from :func:`warm_start_belief` with it."""
    frame = trials
    if "participant" in frame.columns:
        ids = frame["participant"].astype(str)
        if participant is not None:
            frame = frame[ids == str(participant)]
            if frame.empty:
                raise TypeBeliefError([f"no trials of participant {participant!r} in the log"])
        elif ids.nunique() > 1:
            raise TypeBeliefError([f"the log holds {ids.nunique()} participants; name the one to read"])
    elif participant is not None:
        raise TypeBeliefError(["the log has no participant column"])
    missing = [c for c in ("complexity", "robot_action", "experience") if c not in frame.columns]
    if missing:
        raise TypeBeliefError([f"the log has no column {c!r}" for c in missing])
    if session is not None and session not in frame.columns:
        raise TypeBeliefError([f"the log has no column {session!r}"])
    order = [c for c in (session, "trial") if c is not None and c in frame.columns]
    if order:
        frame = frame.sort_values(order, kind="stable")
    c = _codes(frame["complexity"], mixture.complexities, "complexity")
    a = _codes(frame["robot_action"], ACTIONS, "robot_action")
    e = _codes(frame["experience"], EXPERIENCES, "experience")
    o = (
        _codes(frame["human_action"], HUMAN_ACTIONS, "human_action", missing_ok=True)
        if "human_action" in frame.columns
        else np.full(len(frame), UNOBSERVED, dtype=np.int64)
    )
    starts = np.zeros(len(frame), dtype=bool)
    if len(frame):
        starts[0] = True
    if session is not None:
        s = frame[session].astype(str).to_numpy()
        starts[1:] |= s[1:] != s[:-1]
    w = mixture.weights if prior is None else np.asarray(prior, dtype=float)
    upd = BayesUpdate(product_model(mixture))
    b = warm_start_belief(mixture, w)
    for i in range(len(frame)):
        if starts[i] and i > 0:
            b = warm_start_belief(mixture, type_marginal(b, mixture.n_types))
        b = upd.update(b, c[i], a[i], o[i], e[i])
    return type_marginal(b, mixture.n_types)
