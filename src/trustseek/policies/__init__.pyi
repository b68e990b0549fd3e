"""The public names of :mod:`trustseek.policies`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import alpha_vector, base, complexity, envelope, grid_q, kinds, regions, runner, scheduling
from .alpha_vector import AlphaVectorPolicy, FlatAlphaPolicy, TypeAwarePolicy
from .base import POLICY_FORMAT, Policy, PolicyError, ask_bounds, ask_regions
from .complexity import ComplexityPolicy, always_ask, never_ask, randomized
from .grid_q import TrustAwarePolicy
from .kinds import POLICY_KINDS, load_policy, policy_from_dict
from .regions import ask_intervals, threshold
from .runner import PolicyRunner

__all__ = [
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
