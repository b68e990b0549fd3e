"""The policy JSON: one loader per ``kind``, ``policy_from_dict`` and ``load_policy``.

Every policy file has ``format: trustseek.policy/1``, a ``kind`` and its ``complexities``;
the rest depends on the kind.  Files written by earlier versions load unchanged.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ..model.core import ModelError, load_json
from .alpha_vector import AlphaVectorPolicy, FlatAlphaPolicy
from .base import POLICY_FORMAT, Policy
from .complexity import COMPLEXITY_KINDS, ComplexityPolicy
from .grid_q import TrustAwarePolicy
from .schedule import SchedulePolicy

Loader = Callable[[Mapping[str, Any], "str | None"], Policy]

#: kind -> loader of the policy JSON
POLICY_KINDS: dict[str, Loader] = {
    TrustAwarePolicy.kind: TrustAwarePolicy.from_dict,
    AlphaVectorPolicy.kind: AlphaVectorPolicy.from_dict,
    **dict.fromkeys(COMPLEXITY_KINDS, ComplexityPolicy.from_dict),
    FlatAlphaPolicy.kind: FlatAlphaPolicy.from_dict,
    SchedulePolicy.kind: SchedulePolicy.from_dict,
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
    if problems:
        raise ModelError(problems, source)
    kind = d.get("kind")
    loader = POLICY_KINDS.get(kind) if isinstance(kind, str) else None
    if loader is None:
        raise ModelError([f"unknown policy kind {kind!r}; expected one of {list(POLICY_KINDS)}"], source)
    return loader(d, source)


def load_policy(path: str | Path) -> Policy:
    """Read a policy JSON file."""
    d, source = load_json(path)
    return policy_from_dict(d, source)
