"""How much the threshold policy moves when the reported parameters move within their printed precision.

A paper prints its estimates rounded (two decimals in Section V); rounding each one by up to half
a unit of its last decimal moves the optimal policy's threshold.  :func:`sensitivity` measures by
how much, for any two-level trust model and task: each free parameter at either end of its box
alone (a tornado), and jointly the smallest and largest threshold and value over the box by
L-BFGS-B, cross-checked by a Latin-hypercube sample.

The free parameters (:func:`free_parameters`) are one probability per two-outcome row that the
design produces: P(T_1 = high), P(rely | T, C, autonomous), P(T' = high | T, E', C, a), the robot's
success probabilities and the discount (the ``ask`` emissions, the integer rewards and P(C) do not
move).  The quantities are the threshold on P(T = high) below which the policy asks, per
complexity where the printed model's policy has one, and V = Σ_C P(C) V(b_1, C).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np
from scipy.optimize import minimize

from ..errors import TrustseekError
from ..model.core import TrustModel
from ..model.task import Task
from ..parallel import in_processes
from ..pomdp.problem import AssistancePOMDP
from ..vocab import ASK, AUTONOMOUS, RELY, check_belief_update
from .registry import make_solver

#: the value quantity's name (the thresholds are ``threshold[<complexity>]``)
VALUE = "V"
#: the most belief-grid points x solves of the Latin-hypercube check (samples x grid; on the paper's
#: model a sampled solve costs ~5e-5 s a grid point, so 1e7 is about 8 minutes) and of the
#: one-at-a-time and optimised ranges, counted at their fewest evaluations (~1.3e-6 s a point)
MAX_SAMPLED_POINTS = 10_000_000
MAX_RANGE_POINTS = 100_000_000


class SensitivityError(TrustseekError, ValueError):
    """The analysis cannot run on this model or with these settings."""


@dataclass(frozen=True)
class Parameter:
    """One free printed parameter: where it lives, its printed value and its box."""

    name: str
    table: str  # "initial", "emission", "transition", "success" or "discount"
    index: tuple[int, ...]  # the cell that holds the value (its row's other cell holds 1 - value)
    value: float
    lower: float
    upper: float

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "table": self.table, "value": self.value, "lower": self.lower, "upper": self.upper}


def _box(value: float, decimals: int, hi: float = 1.0) -> tuple[float, float]:
    """± half a unit of the last of ``decimals`` printed decimals around ``value``, within [0, hi]."""
    return max(0.0, value - 0.5 * 10.0 ** (-decimals)), min(hi, value + 0.5 * 10.0 ** (-decimals))


def free_parameters(
    model: TrustModel,
    task: Task,
    decimals: int | Mapping[str, int] = 2,
    discount_decimals: int = 3,
    include_task: bool = True,
) -> list[Parameter]:
    """The free printed parameters of a two-level ``model`` and ``task`` with their boxes:
    ± half a unit of the last printed decimal (``decimals``, per parameter name when a mapping;
    names not in it get 2), clipped to [0, 1]."""
    _check(model, task)

    def dec(name: str) -> int:
        return int(decimals.get(name, 2)) if isinstance(decimals, Mapping) else int(decimals)

    out: list[Parameter] = []

    def add(name: str, table: str, index: tuple[int, ...], value: float, places: int | None = None, hi: float = 1.0) -> None:
        out.append(Parameter(name, table, index, value, *_box(value, dec(name) if places is None else places, hi)))

    tl, cl = model.trust_levels, model.complexities
    add(f"P(T1={tl[1]})", "initial", (1,), float(model.initial[1]))
    for c, cn in enumerate(cl):
        for t, tn in enumerate(tl):
            at = (c, AUTONOMOUS, t, RELY)
            add(f"P(rely | T={tn}, C={cn}, autonomous)", "emission", at, float(model.emission[at]))
    experience_names = ("faulty", "reliable")
    for c, cn in enumerate(cl):
        for a, an in ((AUTONOMOUS, "autonomous"), (ASK, "ask")):
            experiences = (0, 1) if a == AUTONOMOUS else (task.ask_experience[c],)
            for e in experiences:
                for t, tn in enumerate(tl):
                    cell = (c, a, e, t, 1)
                    name = f"P(T'={tl[1]} | T={tn}, E'={experience_names[e]}, C={cn}, {an})"
                    add(name, "transition", cell, float(model.transition[cell]))
    if include_task:
        for c, cn in enumerate(task.complexities):
            add(f"p_suc(C={cn})", "success", (c,), float(task.success[c]))
        add("discount", "discount", (), float(task.discount), discount_decimals, 1.0 - 1e-9)
    return out


def _check(model: TrustModel, task: Task) -> None:
    problems = []
    if model.n_trust != 2:
        problems.append(
            f"the sensitivity analysis needs a model with two trust levels (a threshold on P(trust = high)); "
            f"this one has {model.n_trust}: {', '.join(model.trust_levels)}"
        )
    if tuple(model.complexities) != tuple(task.complexities):
        problems.append(f"the model's complexities {list(model.complexities)} differ from the task's {list(task.complexities)}")
    if problems:
        raise SensitivityError(problems)


def apply(model: TrustModel, task: Task, params: Sequence[Parameter], x: Sequence[float] | np.ndarray) -> tuple[TrustModel, Task]:
    """``model`` and ``task`` with each parameter set to the matching value of ``x``."""
    tables = {"initial": model.initial.copy(), "emission": model.emission.copy(), "transition": model.transition.copy()}
    success = task.success.copy()
    discount = task.discount
    for p, v in zip(params, x, strict=True):
        v = float(v)
        if p.table in tables:
            arr = tables[p.table]
            arr[p.index] = v
            other = (*p.index[:-1], 1 - p.index[-1])
            arr[other] = 1.0 - v
        elif p.table == "success":
            success[p.index] = v
        elif p.table == "discount":
            discount = v
    m = model.replace(**tables)
    t = replace(task, success=success, discount=discount)
    return m, t


def evaluate(model: TrustModel, task: Task, belief_update: str = "paper", grid: int = 401) -> dict[str, float]:
    """The thresholds (``threshold[<complexity>]``: NaN when the policy never asks there or its ask
    region is not [0, θ); 1 when it always asks) and V of the optimal policy of ``model`` and ``task``."""
    policy = make_solver("grid", grid=grid, belief_update=belief_update).solve(AssistancePOMDP(model, task))
    out: dict[str, float] = {}
    for cn, th in (policy.thresholds() or {}).items():
        out[f"threshold[{cn}]"] = float("nan") if th is None else float(th)
    b1 = float(model.initial[1])
    v = np.asarray(policy.value(b1), dtype=float)
    out[VALUE] = float(np.dot(task.complexity_probs, v))
    return out


@dataclass
class Sensitivity:
    """What :func:`sensitivity` found.  ``quantities`` are the analysed names; ``nominal`` their values
    at the printed parameters; ``one_at_a_time`` one record per parameter with each quantity at the
    box's two ends; ``joint`` per quantity the optimised min and max with the parameters reaching
    them; ``sampled`` per quantity the min and max over the Latin-hypercube sample."""

    parameters: list[Parameter]
    quantities: list[str]
    nominal: dict[str, float]
    one_at_a_time: list[dict[str, Any]]
    joint: dict[str, dict[str, Any]]
    sampled: dict[str, dict[str, float]]
    settings: dict[str, Any] = field(default_factory=dict)

    def range_of(self, quantity: str) -> tuple[float, float]:
        """The joint range of ``quantity``: the optimised extremes widened by any sampled point beyond them."""
        j, s = self.joint[quantity], self.sampled.get(quantity, {})
        return min(j["min"], s.get("min", np.inf)), max(j["max"], s.get("max", -np.inf))

    def to_dict(self) -> dict[str, Any]:
        return {
            "settings": self.settings,
            "parameters": [p.to_dict() for p in self.parameters],
            "nominal": self.nominal,
            "one_at_a_time": self.one_at_a_time,
            "joint": {q: {**j, "range": list(self.range_of(q))} for q, j in self.joint.items()},
            "sampled": self.sampled,
        }


def sensitivity(
    model: TrustModel,
    task: Task,
    decimals: int | Mapping[str, int] = 2,
    belief_update: str = "paper",
    grid: int = 401,
    samples: int = 256,
    starts: int = 2,
    seed: int = 0,
    parameters: Sequence[Parameter] | None = None,
    jobs: int | None = 1,
) -> Sensitivity:
    """The threshold(s) and V when each free parameter moves within its printed precision,
    alone and jointly (see the module docstring); the parameters moved are ``parameters``, by
    default every free one of the model and the task (:func:`free_parameters`).  ``samples``
    Latin-hypercube points check the optimiser; ``starts`` (>= 1) L-BFGS-B runs per extreme: the
    first from the corner the one-at-a-time effects point to, the second from the printed values,
    further ones from random points of the box.  The extremes run side by side over ``jobs``
    processes (None: all cores), with the same results."""
    check_belief_update(belief_update)
    if grid < 3 or samples < 0 or starts < 1:
        raise SensitivityError([f"need grid >= 3, samples >= 0 and starts >= 1; got {grid}, {samples}, {starts}"])
    params = list(parameters) if parameters is not None else free_parameters(model, task, decimals)
    _check_size(len(params), grid, samples, starts)
    _check(model, task)
    box = _Box(model, task, params, belief_update, grid)
    nominal = box.at(box.x0)
    quantities = [q for q, v in nominal.items() if q == VALUE or 0.0 < v < 1.0]
    if len(quantities) == 1:
        raise SensitivityError(
            [
                "the optimal policy of this model has no threshold in any complexity (it never asks, always asks, "
                f"or asks outside an interval [0, θ)): {_fmt_thresholds(nominal)}; nothing to analyse"
            ]
        )
    oat = _one_at_a_time(box, quantities)
    rng = np.random.default_rng(seed)
    joint = _joint(box, quantities, oat, nominal, starts, rng, jobs)
    sampled = _sampled(box, quantities, samples, rng) if samples else {}
    return Sensitivity(
        parameters=params,
        quantities=quantities,
        nominal={q: nominal[q] for q in quantities},
        one_at_a_time=oat,
        joint=joint,
        sampled=sampled,
        settings={
            "belief_update": belief_update,
            "grid": grid,
            "samples": samples,
            "starts": starts,
            "seed": seed,
            "decimals": dict(decimals) if isinstance(decimals, Mapping) else decimals,
            "evaluations": len(box.cache),
        },
    )


def _check_size(n: int, grid: int, samples: int, starts: int) -> None:
    """Refuse, before any solve, a run beyond :data:`MAX_SAMPLED_POINTS` or
    :data:`MAX_RANGE_POINTS`: the ranges take 2 n + 1 solves one at a time and, per start of each
    extreme of the value and a threshold, five gradients of n + 1 solves (the paper's model: 2,803
    solves in all with the default two starts, against the 881 counted)."""
    problems = []
    if samples * grid > MAX_SAMPLED_POINTS:
        problems.append(
            f"--samples {samples:,} x --grid {grid:,} is {samples * grid:,} belief points to solve, more than "
            f"{MAX_SAMPLED_POINTS:,} (about 8 minutes): fewer samples or a coarser grid"
        )
    fewest = 2 * n + 1 + starts * 2 * 2 * 5 * (n + 1)
    if fewest * grid > MAX_RANGE_POINTS:
        problems.append(
            f"the ranges of {n} parameters from --starts {starts:,} at --grid {grid:,} take at least {fewest * grid:,} "
            f"belief points to solve, more than {MAX_RANGE_POINTS:,} (a few minutes): fewer starts or a coarser grid"
        )
    if problems:
        raise SensitivityError(problems)


class _Box:
    """The parameters' box: the thresholds and V at a point (each point evaluated once), and the
    unit cube u -> lo + u (hi - lo) the optimiser works on."""

    def __init__(self, model: TrustModel, task: Task, params: list[Parameter], belief_update: str, grid: int) -> None:
        self.model, self.task, self.params = model, task, params
        self.belief_update, self.grid = belief_update, grid
        self.x0 = np.array([p.value for p in params])
        self.lo = np.array([p.lower for p in params])
        self.hi = np.array([p.upper for p in params])
        self.width = self.hi - self.lo
        free = self.width > 0
        self.u_nominal = np.where(free, (self.x0 - self.lo) / np.where(free, self.width, 1.0), 0.0)
        self.cache: dict[bytes, dict[str, float]] = {}

    def at(self, x: np.ndarray) -> dict[str, float]:
        x = np.clip(x, self.lo, self.hi)
        key = x.tobytes()
        if key not in self.cache:
            m, t = apply(self.model, self.task, self.params, x)
            self.cache[key] = evaluate(m, t, self.belief_update, self.grid)
        return self.cache[key]

    def to_x(self, u: np.ndarray) -> np.ndarray:
        return self.lo + np.clip(u, 0.0, 1.0) * self.width


def _one_at_a_time(box: _Box, quantities: list[str]) -> list[dict[str, Any]]:
    """Each parameter at its lower and its upper end, the others at their printed values."""
    oat: list[dict[str, Any]] = []
    for i, p in enumerate(box.params):
        rec: dict[str, Any] = {"name": p.name, "value": p.value, "lower": p.lower, "upper": p.upper}
        for end, v in (("at_lower", p.lower), ("at_upper", p.upper)):
            x = box.x0.copy()
            x[i] = v
            r = box.at(x)
            rec[end] = {q: r[q] for q in quantities}
        oat.append(rec)
    return oat


def _joint(
    box: _Box,
    quantities: list[str],
    oat: list[dict[str, Any]],
    nominal: dict[str, float],
    starts: int,
    rng: np.random.Generator,
    jobs: int | None,
) -> dict[str, dict[str, Any]]:
    """Per quantity the least and the greatest over the box (:func:`_extreme`), each extreme from
    ``starts`` points: the one-at-a-time corner, the printed values and random points (drawn here,
    in order, whatever the number of processes); the box's evaluations merged back."""
    n = len(box.params)
    calls = []
    for q in quantities:
        effect = np.nan_to_num(np.array([rec["at_upper"][q] - rec["at_lower"][q] for rec in oat]))
        for sign in (1.0, -1.0):
            corner = (sign * effect < 0).astype(float)
            inits = [corner, box.u_nominal] + [rng.random(n) for _ in range(max(0, starts - 2))]
            calls.append(partial(_extreme, box, q, sign, sign * nominal[q], inits[:starts]))
    found = iter(in_processes(calls, jobs, lambda _i, _done: None))
    out: dict[str, dict[str, Any]] = {}
    for q in quantities:
        res: dict[str, Any] = {}
        for sense, sign in (("min", 1.0), ("max", -1.0)):
            best, best_u, seen = next(found)
            box.cache.update(seen)
            res[sense] = sign * best
            res[f"{sense}_at"] = {p.name: float(v) for p, v in zip(box.params, box.to_x(best_u), strict=True)}
        res["method"] = f"L-BFGS-B from {starts} start(s) per extreme (the one-at-a-time corner first)"
        out[q] = res
    return out


def _extreme(box: _Box, q: str, sign: float, best: float, inits: list[np.ndarray]) -> tuple[float, np.ndarray, dict]:
    """The least of ``sign * q`` over the box by L-BFGS-B on the unit cube from each of ``inits``
    (``best``: its value at the printed point): the value, where, and the points evaluated."""
    n = len(box.params)
    before = set(box.cache)
    best_u = box.u_nominal

    def f(u: np.ndarray) -> float:
        v = box.at(box.to_x(u))[q]
        return sign * v if np.isfinite(v) else np.inf

    for u_init in inits:
        if np.isfinite(f(u_init)) and f(u_init) < best:
            best_u, best = u_init, f(u_init)
        opt = minimize(f, u_init, method="L-BFGS-B", bounds=[(0.0, 1.0)] * n, options={"eps": 1e-3, "maxiter": 30})
        if np.isfinite(opt.fun) and opt.fun < best:
            best_u, best = np.clip(opt.x, 0.0, 1.0), float(opt.fun)
    return best, best_u, {k: v for k, v in box.cache.items() if k not in before}


def _sampled(box: _Box, quantities: list[str], samples: int, rng: np.random.Generator) -> dict[str, dict[str, float]]:
    """The Latin-hypercube check of the optimiser: each quantity's range over ``samples`` points of the box."""
    from scipy.stats import qmc  # scipy.stats is slow to import: only where it is used

    pts = qmc.LatinHypercube(d=len(box.params), seed=rng).random(samples)
    vals: dict[str, list[float]] = {q: [] for q in quantities}
    for u in pts:
        r = box.at(box.to_x(u))
        for q in quantities:
            vals[q].append(r[q])
    sampled: dict[str, dict[str, float]] = {}
    for q in quantities:
        arr = np.asarray(vals[q], dtype=float)
        arr = arr[np.isfinite(arr)]
        sampled[q] = {"n": len(arr), "min": float(arr.min()), "max": float(arr.max())} if len(arr) else {"n": 0}
    return sampled


def _fmt_thresholds(values: Mapping[str, float]) -> str:
    return ", ".join(f"{k} = {v:.4g}" for k, v in values.items())
