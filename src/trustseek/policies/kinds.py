"""The policy JSON: one loader per ``kind``, ``policy_from_dict`` and ``load_policy``.

Every policy file has ``format: trustseek.policy/1``, a ``kind`` and its ``complexities``;
the rest depends on the kind.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..model.jsonfile import ModelError, load_json
from ..vocab import COMPLEXITY_POLICY_KINDS
from .alpha_vector import AlphaVectorPolicy, FlatAlphaPolicy, TypeAwarePolicy
from .base import POLICY_FORMAT, Policy
from .complexity import ComplexityPolicy
from .grid_q import TrustAwarePolicy
from .scheduling import SchedulePolicy

Loader = Callable[[Mapping[str, Any], "str | None"], Policy]

#: kind -> loader of the policy JSON
POLICY_KINDS: dict[str, Loader] = {
    TrustAwarePolicy.kind: TrustAwarePolicy.from_dict,
    AlphaVectorPolicy.kind: AlphaVectorPolicy.from_dict,
    **dict.fromkeys(COMPLEXITY_POLICY_KINDS, ComplexityPolicy.from_dict),
    FlatAlphaPolicy.kind: FlatAlphaPolicy.from_dict,
    SchedulePolicy.kind: SchedulePolicy.from_dict,
    TypeAwarePolicy.kind: TypeAwarePolicy.from_dict,
}


def policy_from_dict(d: Any, source: str | None = None) -> Policy:
    """The policy of a policy JSON object (every problem reported at once, naming ``source``)."""
    if not isinstance(d, Mapping):
        raise ModelError(["a policy must be a JSON object"], source)
    problems = []
    if d.get("format") != POLICY_FORMAT:
        problems.append(f"format is {d.get('format')!r}, expected {POLICY_FORMAT!r}")
    cx = d.get("complexities")
    if not isinstance(cx, list) or not all(isinstance(x, str) for x in cx):
        problems.append(f"complexities must be a list of names, got {cx!r}")
    info, th = d.get("info"), d.get("thresholds")
    if info is not None and not isinstance(info, Mapping):
        problems.append(f"info must be an object of notes, got {type(info).__name__}")
    if th is not None and not (isinstance(th, Mapping) and all(v is None or _number(v) for v in th.values())):
        problems.append(f"thresholds must map each complexity to a number or null, got {th!r}")
    problems += [
        f"{key} holds true or false where a policy holds numbers"
        for key, value in d.items()
        if key not in NOT_NUMBERS and _holds_bool(value)
    ]
    if problems:
        raise ModelError(problems, source)
    kind = d.get("kind")
    loader = POLICY_KINDS.get(kind) if isinstance(kind, str) else None
    if loader is None:
        raise ModelError([f"unknown policy kind {kind!r}; expected one of {list(POLICY_KINDS)}"], source)
    policy = loader(d, source)
    bad = _non_finite(policy)
    if bad:
        raise ModelError(
            [f"{name} has {n} null, NaN or infinite value(s); a policy needs finite numbers" for name, n in bad], source
        )
    return policy


#: the numeric tables of the policy classes (attribute names, as the keys in the file; a schedule
#: policy's ``q`` is under ``states``)
_TABLES = ("q", "q_vectors", "value_vectors")


def _non_finite(policy: Policy) -> list[tuple[str, int]]:
    """The numeric tables of ``policy`` that hold non-finite numbers (a null in the file reads
    as NaN), with how many."""
    out = []
    for attr in _TABLES:
        name = "states" if policy.kind == SchedulePolicy.kind and attr == "q" else attr
        value = getattr(policy, attr, None)
        if value is None:
            continue
        arrays = [np.asarray(a, dtype=float) for a in _leaves(value)]
        n = sum(int(np.size(a) - np.count_nonzero(np.isfinite(a))) for a in arrays)
        if n:
            out.append((name, n))
    return out


#: the keys of a policy file where a ``true``/``false`` is not refused here: texts and notes,
#: and the model and the mixture, which their own readers check
NOT_NUMBERS = ("format", "kind", "complexities", "belief_update", "info", "thresholds", "model", "mixture")


def _holds_bool(value: Any) -> bool:
    """Whether a JSON ``true``/``false`` stands anywhere in ``value`` (numpy and ``int`` checks
    would read it as 1 or 0)."""
    return any(isinstance(leaf, bool) for leaf in _leaves(value))


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _leaves(value: Any) -> list[Any]:
    if isinstance(value, Mapping):  # a schedule policy's Q per state and complexity
        return [leaf for v in value.values() for leaf in _leaves(v)]
    if isinstance(value, (list, tuple)):
        return [leaf for v in value for leaf in _leaves(v)]
    return [value]


def load_policy(path: str | Path) -> Policy:
    """Read a policy JSON file."""
    d, source = load_json(path)
    return policy_from_dict(d, source)
