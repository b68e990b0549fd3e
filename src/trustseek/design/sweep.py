"""Study design and power analysis: replicated pipelines over a grid of designs.

:func:`run_design` runs every replicate of a :class:`DesignConfig` in this process, in local
processes or on a Dask cluster (seeds depend only on the sweep seed, the design point and the
replicate, so the summary is the same whatever runs it) and summarizes per design point the
regret and threshold error with intervals, the power of both tests with exact intervals, the
participants needed and the smallest design meeting the targets.  :func:`ask_search` ranks
experiment 1's ask probabilities at a fixed budget of trials by regret.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from functools import partial
from typing import Any

import numpy as np

from .. import vocab
from ..errors import TrustseekError
from ..model.core import TrustModel
from ..model.jsonfile import json_safe
from ..model.presets import paper_model, paper_task
from ..model.task import Task
from ..parallel import check_jobs, in_processes
from ..reproduction.robustness import solve_policy
from ..solvers.base import one_blas_thread
from ..statistics import finite, mean_interval, share_ci
from .evaluation import evaluate_policy, high_threshold
from .replicate import Experiment1, FitSettings, Study, run_chunk

__all__ = ["TESTS", "DesignConfig", "DesignResult", "ask_search", "ask_search_problems", "participants_needed", "run_design"]

TESTS = ("wilcoxon", "t")
PAPER_ASK = (vocab.PAPER_ASK_PROBABILITIES["low"], vocab.PAPER_ASK_PROBABILITIES["high"])  # (ask_low, ask_high)
MAX_REPLICATES = 10_000  # replicates per design point (as reproduce's --replicates)
MAX_PIPELINES = 1_000_000  # replicate pipelines of a sweep: design points x replicates
MAX_RESTARTS = 1000  # random starts of each replicate's fit (as fit's --restarts)
MAX_GRID = 1_000_001  # belief grid points of each replicate's solve (as solve's --grid)

Progress = Callable[[int, int], None]


@dataclass
class DesignConfig:
    """Every setting of a design sweep (the defaults are the paper's design and a power curve
    over experiment 2's participants)."""

    truth: TrustModel = field(default_factory=paper_model)
    task: Task = field(default_factory=paper_task)
    seed: int = 0
    replicates: int = 100
    # experiment 1 (every combination is a design point)
    participants_1: tuple[int, ...] = (vocab.PAPER_DATA_PARTICIPANTS,)
    trials_1: tuple[int, ...] = (sum(vocab.PAPER_DATA_COUNTS),)
    share_high_1: tuple[float, ...] = (vocab.PAPER_DATA_COUNTS[1] / sum(vocab.PAPER_DATA_COUNTS),)
    ask_low: tuple[float, ...] = (vocab.PAPER_ASK_PROBABILITIES["low"],)
    ask_high: tuple[float, ...] = (vocab.PAPER_ASK_PROBABILITIES["high"],)
    # experiment 2 (evaluated inside every replicate)
    participants_2: tuple[int, ...] = (vocab.PAPER_EVALUATION_PARTICIPANTS, 10, 15, 20, 30, 40, 60)
    trials_2: tuple[int, ...] = (sum(vocab.PAPER_BLOCK_COUNTS),)
    counterbalance: bool = True
    alpha: float = 0.05
    test: str = "wilcoxon"  # the test the targets use
    fit: FitSettings = field(default_factory=FitSettings)
    # targets
    power_target: float = 0.8
    regret_target: float = 0.01  # mean regret at most this share of V*
    level: float = 0.95

    def problems(self) -> list[str]:
        """Every setting out of range, as a message naming its option."""
        p: list[str] = []
        if not 2 <= self.replicates <= MAX_REPLICATES:
            p.append(f"--replicates must be between 2 and {MAX_REPLICATES:,}, got {self.replicates}")
        for name in ("participants_1", "trials_1", "participants_2", "trials_2"):
            vals = getattr(self, name)
            if not vals or min(vals) < 1:
                p.append(f"--{name.replace('_', '-')} needs values >= 1, got {list(vals)}")
        if self.participants_2 and min(self.participants_2) < 2:
            p.append("--participants-2 needs at least 2 participants for a paired test")
        for name in ("share_high_1", "ask_low", "ask_high"):
            vals = getattr(self, name)
            if not vals or any(not 0 <= v <= 1 for v in vals):
                p.append(f"--{name.replace('_', '-')} needs values in [0, 1], got {list(vals)}")
        if not 0 < self.alpha < 1:
            p.append(f"--alpha must lie in (0, 1), got {self.alpha}")
        if self.test not in TESTS:
            p.append(f"--test must be one of {list(TESTS)}, got {self.test!r}")
        if not 0 < self.power_target < 1:
            p.append(f"--power-target must lie in (0, 1), got {self.power_target}")
        if not 0 <= self.regret_target < math.inf:
            p.append(f"--regret-target must be a finite number >= 0, got {self.regret_target}")
        if not 1 <= self.fit.restarts <= MAX_RESTARTS:
            p.append(f"--restarts must be between 1 and {MAX_RESTARTS}, got {self.fit.restarts}")
        if not 0 < self.fit.tol < math.inf:
            p.append(f"--tol must be a finite number > 0, got {self.fit.tol}")
        if not 3 <= self.fit.grid <= MAX_GRID:
            p.append(f"--grid must be between 3 and {MAX_GRID:,} belief points, got {self.fit.grid}")
        if self.fit.belief_update not in vocab.BELIEF_UPDATES:
            p.append(f"--belief-update must be one of {list(vocab.BELIEF_UPDATES)}, got {self.fit.belief_update!r}")
        if self.truth.n_trust != 2:
            p.append(f"a design study needs a true model with two trust levels, got {self.truth.n_trust}")
        if self.task.n_complexity != 2:
            p.append(f"a design study needs a task with two complexities, got {self.task.n_complexity}")
        return p or self.size_problems()

    def size_problems(self, points: int | None = None) -> list[str]:
        """The sweep's sizes beyond the machine, refused before any replicate runs: a simulated
        experiment of more than :data:`~trustseek.simulation.populations.MAX_TRIALS` trials, or
        more than :data:`MAX_PIPELINES` replicate pipelines (``points`` design points; default:
        every combination of experiment 1's grids)."""
        from ..simulation.populations import MAX_TRIALS

        p: list[str] = []
        if points is None:
            points = math.prod(
                len(g) for g in (self.participants_1, self.trials_1, self.share_high_1, self.ask_low, self.ask_high)
            )
        if points * self.replicates > MAX_PIPELINES:
            p.append(
                f"{points:,} design points x {self.replicates:,} replicates is more than {MAX_PIPELINES:,} replicate "
                "pipelines: fewer values in the grids or fewer --replicates"
            )
        one = max(self.participants_1) * max(self.trials_1)
        if one > MAX_TRIALS:
            p.append(
                f"experiment 1 of {max(self.participants_1):,} participants x {max(self.trials_1):,} trials is more than "
                f"{MAX_TRIALS:,} simulated trials: fewer --participants-1 or --trials-1"
            )
        two = max(self.participants_2) * 2 * max(self.trials_2)
        if two > MAX_TRIALS:
            p.append(
                f"experiment 2 of {max(self.participants_2):,} participants x 2 blocks x {max(self.trials_2):,} trials is "
                f"more than {MAX_TRIALS:,} simulated trials: fewer --participants-2 or --trials-2"
            )
        return p

    def designs(self) -> list[Experiment1]:
        """Experiment 1's design points, in order (the index is the point's seed component)."""
        out = []
        for n, t, s, lo, hi in itertools.product(
            self.participants_1, self.trials_1, self.share_high_1, self.ask_low, self.ask_high
        ):
            out.append(Experiment1(int(n), int(t), round(float(t) * float(s)), float(lo), float(hi)))
        return out

    def to_summary(self) -> dict[str, Any]:
        """The settings as the JSON records them (the models last)."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("truth", "task")}
        out = {k: list(v) if isinstance(v, tuple) else v for k, v in out.items()}
        return out | {"fit": asdict(self.fit), "truth": self.truth.to_dict(), "task": self.task.to_dict()}


@dataclass
class DesignResult:
    """What :func:`run_design` produced: the summary and every replicate's record."""

    summary: dict[str, Any]
    replicates: list[dict[str, Any]]
    seconds: float = 0.0


def study_of(cfg: DesignConfig) -> Study:
    """What every replicate shares, with the true model's optimal policy's value and threshold."""
    best = solve_policy(cfg.truth, cfg.task, cfg.fit.belief_update, cfg.fit.grid)
    v_star = evaluate_policy(best, cfg.truth, cfg.task, grid=cfg.fit.evaluation_grid).value
    return Study(
        truth=cfg.truth,
        task=cfg.task,
        fit=cfg.fit,
        participants_2=tuple(int(n) for n in cfg.participants_2),
        trials_2=tuple(int(t) for t in cfg.trials_2),
        counterbalance=cfg.counterbalance,
        alpha=cfg.alpha,
        optimal_value=v_star,
        optimal_threshold=high_threshold(best),
        seed=cfg.seed,
    )


def _even_parts(items: list[Any], workers: int, most: int = 8) -> list[list[Any]]:
    """``items`` in a multiple of ``workers`` parts of at most ``most`` items, as even as possible
    (sizes differ by at most one): every worker gets the same number of tasks of about the same
    length, where fixed-size chunks would leave one worker a task more than the other."""
    n = workers * max(1, math.ceil(len(items) / (most * workers)))
    n = min(n, len(items))
    base, extra = divmod(len(items), n)
    out, i = [], 0
    for k in range(n):
        j = i + base + (1 if k < extra else 0)
        out.append(items[i:j])
        i = j
    return out


def execute(
    study: Study,
    designs: Sequence[Experiment1],
    replicates: int,
    jobs: int = 1,
    client: Any = None,
    progress: Progress | None = None,
) -> list[dict[str, Any]]:
    """``replicates`` replicates of each of ``designs`` (design point: its index), sorted by (point,
    replicate): in this process (``jobs`` = 1), in ``jobs`` local processes, or on the Dask ``client``."""
    check_jobs(jobs, "--jobs")
    items = [(i, d, r) for i, d in enumerate(designs) for r in range(replicates)]
    report = progress or (lambda done, total: None)
    workers = jobs if client is None else max(1, len(client.scheduler_info().get("workers", {})))
    parts = [[item] for item in items] if workers <= 1 else _even_parts(items, workers)
    done = 0

    def finished(part: int) -> None:
        nonlocal done
        done += len(parts[part])
        report(done, len(items))

    if client is None:
        calls = [partial(run_chunk, study, part) for part in parts]
        chunks = in_processes(calls, jobs, lambda part, _: finished(part))
    else:
        from dask.distributed import as_completed as dask_completed

        shared = client.scatter(study, broadcast=True)
        futures = client.map(run_chunk, [shared] * len(parts), parts, pure=False)
        part_of = {fut.key: part for part, fut in enumerate(futures)}
        for fut in dask_completed(futures):
            finished(part_of[fut.key])
        chunks = [fut.result() for fut in futures]
    out = [record for chunk in chunks for record in chunk]
    out.sort(key=lambda r: (r["point"], r["replicate"]))
    return out


@one_blas_thread()
def run_design(
    cfg: DesignConfig | None = None,
    jobs: int = 1,
    client: Any = None,
    progress: Progress | None = None,
) -> DesignResult:
    """Run the sweep of ``cfg`` (``client``: a ``dask.distributed.Client`` to run it on a
    cluster; else ``jobs`` local processes) and summarize it."""
    cfg = cfg or DesignConfig()
    problems = cfg.problems()
    if problems:
        raise TrustseekError(problems)
    t0 = time.perf_counter()
    study = study_of(cfg)
    designs = cfg.designs()
    reps = execute(study, designs, cfg.replicates, jobs=jobs, client=client, progress=progress)
    summary = summarize(cfg, study, designs, reps)
    return DesignResult(summary=json_safe(summary), replicates=json_safe(reps), seconds=time.perf_counter() - t0)


def _interval(values: Sequence[float], level: float) -> dict[str, Any]:
    v = finite(values)
    if not v:
        return {"n": 0, "mean": None, "lo": None, "hi": None}
    return {"n": len(v), **mean_interval(v, level, names=("mean", "lo", "hi")), "median": float(np.median(v))}


def _share(flags: Sequence[bool], level: float) -> dict[str, Any]:
    n, k = len(flags), int(sum(flags))
    lo, hi = share_ci(k, n, level) if n else (float("nan"), float("nan"))
    return {"share": k / n if n else None, "lo": lo, "hi": hi, "n": n}


def _power(pvalues: Sequence[float], diffs: Sequence[float], alpha: float, level: float) -> dict[str, Any]:
    """Share of replicates whose test detects the trust-aware advantage (p < α and a positive
    mean paired difference), with its exact interval."""
    hits = [p < alpha and d > 0 for p, d in zip(pvalues, diffs, strict=True)]
    share = _share(hits, level)
    return {"power": share["share"], "lo": share["lo"], "hi": share["hi"], "detected": int(sum(hits)), "n": share["n"]}


def _of_point(reps: list[dict[str, Any]], point: int) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The replicates of design point ``point``, and those of them that ran to the end (no error)."""
    mine = [r for r in reps if r["point"] == point]
    return mine, [r for r in mine if "error" not in r]


def summarize(cfg: DesignConfig, study: Study, designs: list[Experiment1], reps: list[dict[str, Any]]) -> dict[str, Any]:
    """Per design point: regret, threshold error and power curves; the participants needed for
    the target power; the smallest design meeting the targets."""
    v_star = study.optimal_value
    points: list[dict[str, Any]] = []
    candidates: list[dict[str, Any]] = []
    for i, d in enumerate(designs):
        mine, ok = _of_point(reps, i)
        regret = _interval([r["regret"] for r in ok], cfg.level)
        rel = {k: (None if v is None else v / v_star) for k, v in regret.items() if k in ("mean", "lo", "hi", "median")}
        point: dict[str, Any] = {
            "index": i,
            "experiment1": d.to_dict(),
            "replicates": len(mine),
            "failed": [{"replicate": r["replicate"], "error": r["error"]} for r in mine if "error" in r],
            "regret": regret,
            "relative_regret": rel,
            "threshold_error": _interval([r["threshold_error"] for r in ok], cfg.level),
            "threshold": _interval([r["threshold"] for r in ok], cfg.level),
            "advantage": _interval([r["advantage"] for r in ok], cfg.level),
            "share_positive_advantage": _share([r["advantage"] > 1e-9 for r in ok], cfg.level),
            "experiment2": [],
        }
        for k, trials in enumerate(study.trials_2):
            curve: list[dict[str, Any]] = []
            for n in study.participants_2:
                rows = [t for r in ok for t in r["tests"] if t["trials_2"] == k and t["participants_2"] == n]
                diffs = [t["mean_difference"] for t in rows]
                # a failed replicate detects nothing: it counts in the denominator
                pad = len(mine) - len(ok)
                entry: dict[str, Any] = {
                    "participants": n,
                    "mean_difference": _interval(diffs, cfg.level),
                    **{
                        test: _power([t[test] for t in rows] + [1.0] * pad, diffs + [0.0] * pad, cfg.alpha, cfg.level)
                        for test in TESTS
                    },
                }
                curve.append(entry)
                meets_regret = rel["mean"] is not None and rel["mean"] <= cfg.regret_target
                power = entry[cfg.test]["power"]
                if meets_regret and power is not None and power >= cfg.power_target:
                    candidates.append(
                        {
                            "point": i,
                            "experiment1": d.to_dict(),
                            "participants_2": n,
                            "trials_2": trials,
                            "power": entry[cfg.test],
                            "relative_regret": rel,
                            "cost_trials": d.participants * d.trials + 2 * n * trials,
                        }
                    )
            # the smallest grid value whose power (the estimate, its interval's upper and lower ends) reaches the target
            need = {
                key: next((c["participants"] for c in curve if (c[cfg.test][end] or 0) >= cfg.power_target), None)
                for key, end in (("estimate", "power"), ("lo", "hi"), ("hi", "lo"))
            }
            point["experiment2"].append({"trials_per_block": trials, "curve": curve, "participants_for_power": need})
        points.append(point)
    smallest = min(candidates, key=lambda c: (c["cost_trials"], c["point"], c["participants_2"])) if candidates else None
    return {
        "config": cfg.to_summary(),
        "optimal": {"value": v_star, "threshold": study.optimal_threshold},
        "points": points,
        "smallest_design": smallest,
        "targets": {
            "power": cfg.power_target,
            "relative_regret": cfg.regret_target,
            "test": cfg.test,
            "alpha": cfg.alpha,
            "met": smallest is not None,
        },
        "notes": [
            "regret = V*(b0) - V(b0) of the estimated policy under the true model (exact evaluation), "
            "the estimated policy tracking trust with the fitted model",
            "advantage = V(b0) of the estimated policy - V(b0) of the trust-agnostic policy estimated from the same data, "
            "both exact under the true model; power cannot exceed the share of replicates with a positive advantage "
            "by much as participants grow",
            "power = share of replicates with p < alpha and a positive mean paired difference; exact (Clopper-Pearson) intervals",
            "participants_for_power: smallest grid value whose power (estimate / upper end / lower end of its interval) "
            "reaches the target; lo and hi bracket the estimate",
        ],
    }


def _search_of(
    cfg: DesignConfig, ask_low: Iterable[float], ask_high: Iterable[float]
) -> tuple[DesignConfig, list[tuple[float, float]], list[str]]:
    """The ask-probability search's sweep: its settings (experiment 1's budget, the first value
    of each other grid of ``cfg``), its (ask_low, ask_high) grid with the paper's, and every
    setting out of range."""
    lows, highs = [float(v) for v in ask_low], [float(v) for v in ask_high]
    problems = [
        f"{name} needs values in [0, 1], got {vals}"
        for name, vals in (("--search-ask-low", lows), ("--search-ask-high", highs))
        if not vals or any(not 0 <= v <= 1 for v in vals)
    ]
    grid = [(lo, hi) for lo in lows for hi in highs]
    if PAPER_ASK not in grid:
        grid.append(PAPER_ASK)
    firsts = ("participants_1", "trials_1", "share_high_1", "participants_2", "trials_2")
    sub = replace(cfg, **{name: getattr(cfg, name)[:1] for name in firsts})
    return sub, grid, problems or sub.problems() or sub.size_problems(len(grid))


def participants_needed(experiment2: dict[str, Any], power: float, test: str) -> str:
    """The participants experiment 2 needs for ``power``, in words: the smallest grid value whose
    power reaches it, with the grid values where its interval's upper and lower ends do; when no
    value reaches it, the largest value, its power, and a wider grid to try."""
    need, curve = experiment2["participants_for_power"], experiment2["curve"]
    if need["estimate"] is None:
        last = curve[-1]
        reached, lo, hi = (_two(last[test][k]) for k in ("power", "lo", "hi"))
        wider = ",".join(str(last["participants"] * k) for k in (1, 2, 4, 8))
        return (
            f"more than {last['participants']}, the largest of the grid (power {reached} [{lo}, {hi}] there): widen it, "
            f"e.g. --participants-2 {wider}"
        )
    ends = [f"{need['lo']} by the interval's upper end"]
    ends.append(f"{need['hi']} by its lower end" if need["hi"] is not None else "beyond the grid by its lower end")
    return f"{need['estimate']} ({'; '.join(ends)})"


def _two(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.2f}"


def ask_search_problems(cfg: DesignConfig, ask_low: Iterable[float], ask_high: Iterable[float]) -> list[str]:
    """Every setting of :func:`ask_search` out of range (a caller's check before any work)."""
    return _search_of(cfg, ask_low, ask_high)[2]


@one_blas_thread()
def ask_search(
    cfg: DesignConfig,
    ask_low: Iterable[float],
    ask_high: Iterable[float],
    jobs: int = 1,
    client: Any = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """The data-collection design search: every (ask_low, ask_high) at experiment 1's budget
    (the first of ``cfg``'s participants and trials), ranked by the mean regret of the estimated
    policy; the best with its interval next to the paper's 0.10 / 0.40, and the Welch interval of
    the paper's regret minus the best's (independent replicates: seeds differ by design point)."""
    sub, grid, problems = _search_of(cfg, ask_low, ask_high)
    if problems:
        raise TrustseekError(problems)
    study = study_of(sub)
    designs = [replace(sub.designs()[0], ask_low=lo, ask_high=hi) for lo, hi in grid]
    reps = execute(study, designs, sub.replicates, jobs=jobs, client=client, progress=progress)
    rows: list[dict[str, Any]] = []
    regrets: list[np.ndarray] = []
    for i, d in enumerate(designs):
        mine, ok = _of_point(reps, i)
        regrets.append(np.array([r["regret"] for r in ok]))
        regret = _interval([r["regret"] for r in ok], sub.level)
        rows.append(
            {
                "ask_low": d.ask_low,
                "ask_high": d.ask_high,
                "regret": regret,
                "relative_regret": None if regret["mean"] is None else regret["mean"] / study.optimal_value,
                "threshold_error": _interval([r["threshold_error"] for r in ok], sub.level),
                "failed": len(mine) - len(ok),
            }
        )
    ranked = sorted(rows, key=lambda r: math.inf if r["regret"]["mean"] is None else r["regret"]["mean"])
    best = ranked[0]
    at_paper = next(r for r in rows if (r["ask_low"], r["ask_high"]) == PAPER_ASK)
    i_best, i_paper = rows.index(best), rows.index(at_paper)
    difference: dict[str, Any] = {"mean": None, "lo": None, "hi": None}
    if i_best != i_paper and len(regrets[i_best]) > 1 and len(regrets[i_paper]) > 1:
        from scipy.stats import ttest_ind  # slow to import: only where it is used

        welch = ttest_ind(regrets[i_paper], regrets[i_best], equal_var=False)
        ci = welch.confidence_interval(sub.level)
        difference = {
            "mean": float(regrets[i_paper].mean() - regrets[i_best].mean()),
            "lo": float(ci.low),
            "hi": float(ci.high),
            "p_value": float(welch.pvalue),
        }
    # near the best: the paper's choice is the best, or the interval of (paper - best) reaches 0
    near = i_best == i_paper or (difference["lo"] is not None and difference["lo"] <= 0)
    return json_safe(
        {
            "budget": {"participants": sub.participants_1[0], "trials": sub.trials_1[0]},
            "replicates": sub.replicates,
            "seed": sub.seed,
            "optimal_value": study.optimal_value,
            "rows": rows,
            "ranked": [(r["ask_low"], r["ask_high"]) for r in ranked],
            "best": best,
            "paper": at_paper,
            "paper_minus_best": difference,
            "paper_near_best": bool(near),
        }
    )
