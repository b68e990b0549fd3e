"""Policies: what the robot does on the next trial, their JSON kinds, and ``PolicyRunner``."""

from .core import (
    ComplexityPolicy,
    Policy,
    PolicyRunner,
    TrustAwarePolicy,
    always_ask,
    load_policy,
    never_ask,
    policy_from_dict,
    randomized,
)

__all__ = [
    "ComplexityPolicy",
    "Policy",
    "PolicyRunner",
    "TrustAwarePolicy",
    "always_ask",
    "load_policy",
    "never_ask",
    "policy_from_dict",
    "randomized",
]
