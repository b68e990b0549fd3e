"""One machine-readable summary of a solved policy: what ``trustseek solve --json`` prints.

Every summary names the policy, its belief update, where it asks and the trust-agnostic
policy of the same model for comparison.  A policy that carries a certificate (``certified_gap``
in its ``info``: the ``alpha``, ``certified-grid`` and ``point`` solvers) adds its value bounds
and threshold intervals; one without adds the values at b = 1 and at the initial belief and the
solver's own report.
"""

from __future__ import annotations

from typing import Any

from ..policies.base import Policy, ask_regions
from ..pomdp.problem import AssistancePOMDP
from .registry import make_solver


def summarize(policy: Policy, pomdp: AssistancePOMDP) -> dict[str, Any]:
    """The summary of ``policy`` solved for ``pomdp`` (any number of trust levels)."""
    info = policy.info
    agnostic = make_solver("trust-agnostic").solve(pomdp).to_dict()["p_ask"]
    name = "trust-aware" if policy.belief_update is not None else policy.kind
    two_levels = pomdp.n_trust == 2
    if "certified_gap" not in info:
        b0 = float(pomdp.model.initial[-1])
        out: dict[str, Any] = {"policy": name, "belief_update": policy.belief_update, **ask_regions(policy)}
        if policy.belief_update is not None:
            out["value_at_b1"] = _values_at_b1(policy)
            out["initial_belief"] = b0
            out["value_at_initial_belief"] = float(policy.value(b0) @ pomdp.complexity_probs)
        out["solver"] = info
        out["trust_agnostic"] = agnostic
        return out
    out = {
        "policy": name,
        "solver": info.get("solver"),
        "belief_update": policy.belief_update,
        "certified_gap": info.get("certified_gap"),
        "value_bounds_at_initial_belief": info.get("value_bounds_at_initial_belief"),
        "initial_belief": dict(zip(pomdp.trust_levels, map(float, pomdp.model.initial), strict=True)),
    }
    if two_levels:
        regions = ask_regions(policy)
        out["thresholds"] = regions["thresholds"]
        out["threshold_intervals"] = info.get("threshold_intervals")
        out["ask_intervals"] = regions["ask_intervals"]
        out["value_at_b1"] = _values_at_b1(policy)
    out["trust_agnostic"] = agnostic
    out["info"] = {k: v for k, v in info.items() if k not in ("thresholds", "threshold_intervals")}
    return out


def _values_at_b1(policy: Policy) -> dict[str, float]:
    v1 = policy.value(1.0)
    return {cn: float(v1[c]) for c, cn in enumerate(policy.complexities)}
