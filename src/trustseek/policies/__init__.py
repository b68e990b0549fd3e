"""Policies: what the robot does on the next trial.

* :mod:`.base`         -- the ``Policy`` interface every policy implements, ``PolicyError``;
* :mod:`.thresholds`   -- ask intervals and thresholds, extracted once for every policy;
* :mod:`.regions`      -- a policy's ask regions as simulator bounds and as JSON;
* :mod:`.grid_q`       -- ``TrustAwarePolicy``: greedy in Q tabulated on a belief grid;
* :mod:`.alpha_vector` -- ``AlphaVectorPolicy`` (and ``FlatAlphaPolicy`` for standard files);
* :mod:`.complexity`   -- ``ComplexityPolicy``: trust-agnostic, randomized, always/never ask;
* :mod:`.type_aware`   -- ``TypeAwarePolicy``: alpha vectors over (type, trust) for an unknown supervisor type;
* :mod:`.kinds`        -- the policy JSON: one loader per kind, ``policy_from_dict``, ``load_policy``;
* :mod:`.runner`       -- ``PolicyRunner``: a policy with its live belief, trial by trial.

Policies never solve anything: the solvers (``trustseek.solvers``) build them.
"""

from .alpha_vector import AlphaVectorPolicy, FlatAlphaPolicy
from .base import POLICY_FORMAT, Policy, PolicyError
from .complexity import COMPLEXITY_KINDS, ComplexityPolicy, always_ask, never_ask, randomized
from .grid_q import TrustAwarePolicy
from .kinds import POLICY_KINDS, load_policy, policy_from_dict
from .regions import ask_bounds, ask_regions
from .runner import PolicyRunner
from .thresholds import ask_intervals, threshold
from .type_aware import TypeAwarePolicy

__all__ = [
    "COMPLEXITY_KINDS",
    "POLICY_FORMAT",
    "POLICY_KINDS",
    "AlphaVectorPolicy",
    "ComplexityPolicy",
    "FlatAlphaPolicy",
    "Policy",
    "PolicyError",
    "PolicyRunner",
    "TrustAwarePolicy",
    "TypeAwarePolicy",
    "always_ask",
    "ask_bounds",
    "ask_intervals",
    "ask_regions",
    "load_policy",
    "never_ask",
    "policy_from_dict",
    "randomized",
    "threshold",
]
