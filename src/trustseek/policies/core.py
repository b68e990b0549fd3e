"""Policies: what the robot does on the next trial.

Every policy answers one question -- given the current belief over trust and the
trial's complexity, ``autonomous`` or ``ask``? -- through

* ``actions(beliefs, complexities, rng)``: vectorized, beliefs (n, K), complexity indices (n,);
* ``action(belief, complexity, rng)``: one decision (complexity by index or name).

Policies that need the belief name their ``belief_update``; :class:`PolicyRunner`
pairs a policy with its belief updater and consumes each trial's events, which
is how simulations, the experiment server and a robot run a policy.

Kinds (the ``kind`` field of the policy JSON):

* ``trust-aware``: greedy in Q(b, C, a) of the solved belief MDP;
* ``trust-agnostic``: Section VI-A, one fixed action per complexity, the one with
  the larger expected one-trial reward given P(intervene | C, autonomous);
* ``randomized``: the data-collection policy, ask with probability p_ask[C]
  (paper: 0.10 in low, 0.40 in high complexity);
* ``always-ask`` and ``never-ask``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Protocol, Sequence

import numpy as np

from ..pomdp.belief import make_updater, to_vector
from ..vocab import BELIEF_UPDATES, PAPER_ASK_PROBABILITIES
from ..model.core import ACTIONS, ASK, AUTONOMOUS, HUMAN_ACTIONS, INTERVENE, EXPERIENCES, ModelError, Task, TrustModel, json_safe

POLICY_FORMAT = "trustseek.policy/1"


class Policy(Protocol):
    kind: str
    complexities: tuple[str, ...]
    belief_update: str | None
    model: TrustModel | None

    def actions(self, beliefs: np.ndarray, complexities: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray: ...

    def action(self, belief, complexity, rng: np.random.Generator | None = None) -> int: ...

    def to_dict(self) -> dict[str, Any]: ...


class _PolicyBase:
    kind = ""
    complexities: tuple[str, ...] = ()
    belief_update: str | None = None
    model: TrustModel | None = None

    def _cindex(self, complexity) -> int:
        if isinstance(complexity, str):
            try:
                return self.complexities.index(complexity)
            except ValueError:
                raise KeyError(f"unknown complexity {complexity!r}; expected one of {list(self.complexities)}") from None
        c = int(complexity)
        if not 0 <= c < len(self.complexities):
            raise KeyError(f"complexity index {c} out of range for {list(self.complexities)}")
        return c

    def action(self, belief, complexity, rng=None) -> int:
        n_trust = self.model.n_trust if self.model is not None else 2
        b = to_vector(belief, n_trust)[None, :] if belief is not None else np.full((1, n_trust), np.nan)
        return int(self.actions(b, np.array([self._cindex(complexity)]), rng)[0])

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(json_safe(self.to_dict()), indent=1, allow_nan=False) + "\n", encoding="utf-8")

    def describe(self) -> str:
        return self.kind


# --------------------------------------------------------------------------- trust-aware


class TrustAwarePolicy(_PolicyBase):
    """Greedy in the solved Q(b, C, a) on a belief grid over P(trust = high) (two trust levels)."""

    kind = "trust-aware"

    def __init__(
        self,
        grid: np.ndarray,
        q: np.ndarray,
        model: TrustModel,
        complexities: Sequence[str],
        belief_update: str,
        info: Mapping[str, Any] | None = None,
    ):
        self.grid = np.asarray(grid, dtype=float)
        self.q = np.asarray(q, dtype=float)
        self.model = model
        self.complexities = tuple(complexities)
        self.belief_update = belief_update
        self.info = dict(info or {})
        if self.q.shape != (len(self.grid), len(self.complexities), 2):
            raise ModelError([f"q has shape {self.q.shape}, expected {(len(self.grid), len(self.complexities), 2)}"])

    @classmethod
    def from_solution(cls, sol, model: TrustModel, task: Task) -> "TrustAwarePolicy":
        info = {
            "solver": "grid",
            "method": sol.method,
            "grid_points": len(sol.grid),
            "iterations": sol.iterations,
            "bellman_residual": sol.residual,
            "error_bound": sol.error_bound,
            "seconds": sol.seconds,
            "discount": task.discount,
        }
        return cls(sol.grid, sol.q, model, task.complexities, sol.belief_update, info)

    # -- evaluation --------------------------------------------------------
    def q_values(self, b_high: np.ndarray | float) -> np.ndarray:
        """Q at P(trust = high) = b_high, linearly interpolated; shape (..., N, 2)."""
        x = np.clip(np.asarray(b_high, dtype=float), 0.0, 1.0)
        G = len(self.grid)
        pos = x * (G - 1)
        j = np.minimum(np.floor(pos).astype(np.int64), G - 2)
        f = (pos - j)[..., None, None]
        return self.q[j] * (1 - f) + self.q[j + 1] * f

    def value(self, b_high, complexity=None) -> np.ndarray | float:
        """V(b, C) = max_a Q(b, C, a) at P(trust = high) = b_high: shape (..., N), or (...) for
        one complexity."""
        v = self.q_values(b_high).max(axis=-1)
        return v if complexity is None else v[..., self._cindex(complexity)]

    def actions(self, beliefs, complexities, rng=None) -> np.ndarray:
        beliefs = np.asarray(beliefs, dtype=float)
        complexities = np.asarray(complexities, dtype=np.int64)
        x = np.clip(beliefs[..., -1], 0.0, 1.0)
        G = len(self.grid)
        pos = x * (G - 1)
        j = np.minimum(np.floor(pos).astype(np.int64), G - 2)
        f = pos - j
        d = self.q[:, :, ASK] - self.q[:, :, AUTONOMOUS]  # (G, N): advantage of asking
        adv = d[j, complexities] * (1 - f) + d[j + 1, complexities] * f
        return np.where(adv > 0, ASK, AUTONOMOUS).astype(np.int64)

    def ask_intervals(self) -> dict[str, list[tuple[float, float]]]:
        """Per complexity, the belief intervals where the policy asks (ends found by linear
        interpolation of the advantage Q(ask) - Q(autonomous) between grid points)."""
        d = self.q[:, :, ASK] - self.q[:, :, AUTONOMOUS]
        g = self.grid
        out = {}
        for c, cn in enumerate(self.complexities):
            dc = d[:, c]
            ask = dc > 0
            intervals = []
            i = 0
            G = len(g)
            while i < G:
                if not ask[i]:
                    i += 1
                    continue
                start = i
                while i < G and ask[i]:
                    i += 1
                lo = g[0] if start == 0 else _crossing(g, dc, start - 1)
                hi = g[-1] if i == G else _crossing(g, dc, i - 1)
                intervals.append((float(lo), float(hi)))
            out[cn] = intervals
        return out

    def thresholds(self) -> dict[str, float | None]:
        """Per complexity, the belief in high trust below which the policy asks (``None`` when it
        never asks; 1.0 when it always asks; NaN when the ask region is not of the form [0, θ):
        see :meth:`ask_intervals`)."""
        out: dict[str, float | None] = {}
        for cn, iv in self.ask_intervals().items():
            if not iv:
                out[cn] = None
            elif len(iv) == 1 and iv[0][0] == self.grid[0]:
                out[cn] = iv[0][1]
            else:
                out[cn] = float("nan")  # not a threshold policy; see ask_intervals()
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": POLICY_FORMAT,
            "kind": self.kind,
            "complexities": list(self.complexities),
            "belief_update": self.belief_update,
            "thresholds": self.thresholds(),
            "info": self.info,
            "model": self.model.to_dict(),
            "grid": {"points": len(self.grid)},
            "q": {
                cn: {an: [round(float(v), 12) for v in self.q[:, c, a]] for a, an in enumerate(ACTIONS)}
                for c, cn in enumerate(self.complexities)
            },
        }


def _crossing(g: np.ndarray, d: np.ndarray, i: int) -> float:
    """Where the line through (g[i], d[i]) and (g[i+1], d[i+1]) crosses zero."""
    d0, d1 = d[i], d[i + 1]
    if d0 == d1:
        return float(g[i])
    t = d0 / (d0 - d1)
    return float(g[i] + t * (g[i + 1] - g[i]))


# --------------------------------------------------------------------------- complexity-only policies


class ComplexityPolicy(_PolicyBase):
    """A policy that looks only at the complexity: ask with probability p_ask[C].

    Covers ``trust-agnostic`` (p_ask in {0, 1}), ``randomized``, ``always-ask`` and
    ``never-ask``.  It ignores the belief.
    """

    def __init__(self, kind: str, complexities: Sequence[str], p_ask: Sequence[float], info: Mapping[str, Any] | None = None):
        self.kind = kind
        self.complexities = tuple(complexities)
        self.p_ask = np.asarray(p_ask, dtype=float)
        self.info = dict(info or {})
        problems = []
        if self.p_ask.shape != (len(self.complexities),):
            problems.append(f"p_ask needs one entry per complexity {list(self.complexities)}, got {self.p_ask.tolist()}")
        elif np.any(~np.isfinite(self.p_ask)) or np.any(self.p_ask < 0) or np.any(self.p_ask > 1):
            problems.append(f"p_ask must lie in [0, 1], got {self.p_ask.tolist()}")
        if kind not in COMPLEXITY_KINDS:
            problems.append(f"unknown policy kind {kind!r}")
        if problems:
            raise ModelError(problems)

    def actions(self, beliefs, complexities, rng=None) -> np.ndarray:
        complexities = np.asarray(complexities, dtype=np.int64)
        p = self.p_ask[complexities]
        if np.all((p == 0) | (p == 1)):
            return (p == 1).astype(np.int64)
        if rng is None:
            raise ValueError(f"the {self.kind} policy is random: pass a numpy Generator as rng")
        return (rng.random(p.shape) < p).astype(np.int64)

    def describe(self) -> str:
        parts = ", ".join(f"{cn}: {_describe_p(p)}" for cn, p in zip(self.complexities, self.p_ask))
        return f"{self.kind} ({parts})"

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": POLICY_FORMAT,
            "kind": self.kind,
            "complexities": list(self.complexities),
            "p_ask": {cn: float(p) for cn, p in zip(self.complexities, self.p_ask)},
            "info": self.info,
        }


def _describe_p(p: float) -> str:
    if p == 0:
        return "never ask"
    if p == 1:
        return "always ask"
    return f"ask w.p. {p:g}"


COMPLEXITY_KINDS = ("trust-agnostic", "randomized", "always-ask", "never-ask")


def always_ask(complexities: Sequence[str] = ("low", "high")) -> ComplexityPolicy:
    return ComplexityPolicy("always-ask", complexities, [1.0] * len(complexities))


def never_ask(complexities: Sequence[str] = ("low", "high")) -> ComplexityPolicy:
    return ComplexityPolicy("never-ask", complexities, [0.0] * len(complexities))


def randomized(p_ask: Mapping[str, float] | None = None) -> ComplexityPolicy:
    """The data-collection policy of Section V (default: ask w.p. 0.10 in low, 0.40 in high)."""
    p_ask = dict(PAPER_ASK_PROBABILITIES if p_ask is None else p_ask)
    return ComplexityPolicy("randomized", list(p_ask), list(p_ask.values()))


def agnostic_from_intervention_rates(task: Task, p_intervene: Sequence[float], source: str = "") -> ComplexityPolicy:
    """Section VI-A: per complexity, compare the expected one-trial reward of acting
    autonomously, P(rely|C)·(p_suc R_success + (1-p_suc) R_failure) + P(intervene|C) R_intervene,
    with that of asking, and pick the larger (autonomous on ties)."""
    p_int = np.asarray(p_intervene, dtype=float)
    rw = task.rewards
    s = task.success
    r_auto = (1 - p_int) * (s * rw.autonomous_success + (1 - s) * rw.autonomous_failure) + p_int * rw.intervene
    r_ask = np.full_like(r_auto, rw.ask)
    p_ask = (r_ask > r_auto).astype(float)
    info = {
        "p_intervene": {cn: float(p) for cn, p in zip(task.complexities, p_int)},
        "expected_reward": {
            cn: {"autonomous": float(ra), "ask": float(rk)} for cn, ra, rk in zip(task.complexities, r_auto, r_ask)
        },
        "source": source,
    }
    return ComplexityPolicy("trust-agnostic", task.complexities, p_ask, info)


def trust_occupancy(model: TrustModel, task: Task, data_policy: ComplexityPolicy, horizon: int) -> np.ndarray:
    """Average over trials 1..horizon of the trust marginal P(T_t) when ``data_policy`` runs
    (actions depend on complexity only, so the trust marginal is a Markov chain)."""
    from ..pomdp.problem import AssistancePOMDP

    pomdp = AssistancePOMDP(model, task)
    k = pomdp.kernel.sum(axis=(3, 4))  # [c, a, t, u]
    pa = np.stack([1 - data_policy.p_ask, data_policy.p_ask], axis=1)  # [c, a]
    M = np.einsum("c,ca,catu->tu", task.complexity_probs, pa, k)
    p = np.array(model.initial, dtype=float)
    acc = np.zeros_like(p)
    for _ in range(horizon):
        acc += p
        p = p @ M
    return acc / horizon


def trust_agnostic(
    model: TrustModel,
    task: Task,
    data_policy: ComplexityPolicy | None = None,
    horizon: int = 71,
) -> ComplexityPolicy:
    """The optimal trust-agnostic policy with P(intervene | C, autonomous) taken from ``model``,
    averaged over the trust distribution that the data-collection design produces (by default
    the paper's: randomized 0.10/0.40 policy, 71 trials)."""
    data_policy = data_policy or randomized(dict(zip(task.complexities, [PAPER_ASK_PROBABILITIES.get(c, 0.25) for c in task.complexities])))
    occ = trust_occupancy(model, task, data_policy, horizon)
    p_int = np.einsum("t,ct->c", occ, model.emission[:, AUTONOMOUS, :, INTERVENE])
    pol = agnostic_from_intervention_rates(task, p_int, source=f"model, trust averaged over {horizon} trials of the {data_policy.describe()} policy")
    return pol


def trust_agnostic_from_data(trials, task: Task) -> ComplexityPolicy:
    """The optimal trust-agnostic policy with P(intervene | C, autonomous) estimated from logged
    trials (a DataFrame with columns ``complexity``, ``robot_action`` and ``human_action``)."""
    p_int = []
    for cn in task.complexities:
        rows = trials[(trials["complexity"] == cn) & (trials["robot_action"] == "autonomous") & trials["human_action"].notna()]
        if len(rows) == 0:
            raise ValueError(f"no autonomous trials with a recorded human action in complexity {cn!r}")
        p_int.append(float((rows["human_action"] == "intervene").mean()))
    return agnostic_from_intervention_rates(task, p_int, source=f"data, {len(trials)} trials")


# --------------------------------------------------------------------------- JSON


def policy_from_dict(d: Any, source: str | None = None) -> Policy:
    if not isinstance(d, Mapping):
        raise ModelError(["a policy must be a JSON object"], source)
    problems = []
    if d.get("format") != POLICY_FORMAT:
        problems.append(f"format is {d.get('format')!r}, expected {POLICY_FORMAT!r}")
    kind = d.get("kind")
    cx = d.get("complexities")
    if not isinstance(cx, list) or not all(isinstance(x, str) for x in cx):
        problems.append(f"complexities must be a list of names, got {cx!r}")
    if problems:
        raise ModelError(problems, source)
    if kind in COMPLEXITY_KINDS:
        p = d.get("p_ask")
        if not isinstance(p, Mapping) or list(p) != cx:
            raise ModelError([f"p_ask must map each of {cx} to a probability, got {p!r}"], source)
        try:
            return ComplexityPolicy(kind, cx, [p[c] for c in cx], d.get("info"))
        except ModelError as exc:
            raise ModelError(exc.problems, source) from None
    if kind == "trust-aware":
        model = TrustModel.from_dict(d.get("model"), source)
        bu = d.get("belief_update")
        if bu not in BELIEF_UPDATES:
            raise ModelError([f"belief_update is {bu!r}, expected one of {list(BELIEF_UPDATES)}"], source)
        q = d.get("q")
        try:
            arr = np.array([[q[c][a] for a in ACTIONS] for c in cx], dtype=float).transpose(2, 0, 1)
        except (KeyError, TypeError, ValueError):
            raise ModelError([f"q must map each complexity {cx} and action {list(ACTIONS)} to a list of numbers"], source) from None
        grid = np.linspace(0.0, 1.0, arr.shape[0])
        return TrustAwarePolicy(grid, arr, model, cx, bu, d.get("info"))
    if kind == "alpha-vector":
        from ..solvers.alpha import AlphaVectorPolicy

        return AlphaVectorPolicy.from_dict(d, source)
    raise ModelError([f"unknown policy kind {kind!r}; expected one of {['trust-aware', *COMPLEXITY_KINDS]}"], source)


def load_policy(path: str | Path) -> Policy:
    from ..model.core import load_json

    d, source = load_json(path)
    return policy_from_dict(d, source)


# --------------------------------------------------------------------------- running a policy


@dataclass
class PolicyRunner:
    """A policy with its live belief: ``decide`` before a trial, ``observe`` after it.

    For complexity-only policies the belief is still tracked when a model is given
    (useful for logging), with the ``bayes`` update unless the policy names one.
    """

    policy: Policy
    model: TrustModel | None = None
    belief_update: str | None = None
    rng: np.random.Generator = field(default_factory=np.random.default_rng)
    belief: np.ndarray | None = None
    trial: int = 0

    def __post_init__(self) -> None:
        self.model = self.model or getattr(self.policy, "model", None)
        self.belief_update = self.belief_update or self.policy.belief_update or "bayes"
        self._updater = make_updater(self.belief_update, self.model) if self.model is not None else None
        if self.belief is None and self._updater is not None:
            self.belief = self._updater.initial()
        if self.policy.belief_update is not None and self._updater is None:
            raise ValueError("this policy needs a trust model for its belief update")

    def decide(self, complexity) -> str:
        """The robot action (``autonomous`` or ``ask``) for the next trial."""
        c = self.policy._cindex(complexity)
        return ACTIONS[self.policy.action(self.belief, c, self.rng)]

    def observe(self, complexity, action: str, human_action: str | None, experience: str) -> np.ndarray | None:
        """Update the belief from one trial's events; returns the new belief (or None without a model)."""
        c = self.policy._cindex(complexity)
        if action not in ACTIONS:
            raise ValueError(f"robot action must be one of {list(ACTIONS)}, got {action!r}")
        if human_action is not None and human_action not in HUMAN_ACTIONS:
            raise ValueError(f"human action must be one of {list(HUMAN_ACTIONS)} or None, got {human_action!r}")
        if experience not in EXPERIENCES:
            raise ValueError(f"experience must be one of {list(EXPERIENCES)}, got {experience!r}")
        self.trial += 1
        if self._updater is None:
            return None
        o = -1 if human_action is None else HUMAN_ACTIONS.index(human_action)
        self.belief = self._updater.update(self.belief, c, ACTIONS.index(action), o, EXPERIENCES.index(experience))
        return self.belief
