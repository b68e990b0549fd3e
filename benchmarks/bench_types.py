"""Benchmark of planning for a person of unknown supervisor type, and of the reachable solver.

    python benchmarks/bench_types.py             # time limit 60 s per solve
    python benchmarks/bench_types.py --quick     # time limit 15 s per solve
    python benchmarks/bench_types.py --sarsop /path/to/pomdpsol   # also SARSOP on the same problems

* the type-aware solve for M = 3 types (the paper's supervisor, the conservative one and
  "midway", their average, in shares 0.5 / 0.3 / 0.2), K = 2 trust levels, to a bound gap of
  1e-3 at b0 (target < 1 s) with the types solver (its gap against time: one line per grid
  resolution) and the reachable solver, next to the point solver on the same problem with the
  same time limit (the in-run baseline);
* the same for M = 2 (the ``paper+conservative`` preset);
* single-type models with K = 3 (the shipped three-level example) and K = 4 (a four-level chain
  built from the paper's numbers, below): no type structure, so the types solver's cap is the
  fast informed bound alone; same gap and time limit.

Each line: solver, seconds (wall and CPU, one core), the bounds at b0 and the gap reached.
The types solver is run once before timing (its compiled bound is cached on disk).
With ``--sarsop``, each type-aware problem is also written as POMDPX (``write_pomdpx``) and
solved by SARSOP's ``pomdpsol`` (built from its public source; not a dependency) with the same
target precision and time limit; its bounds are at the same b0 (complexity a state variable
with P(C) at the start, so its value is Σ_C P(C) V(b0, C), as ours).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from trustseek.data import example_path
from trustseek.interop.files import write_pomdpx
from trustseek.model import TypeMixture, conservative_model, paper_conservative_mixture, paper_model, paper_task
from trustseek.model.core import TrustModel, trust_model
from trustseek.model.task import Task
from trustseek.pomdp import AssistancePOMDP
from trustseek.pomdp.supervisor_types import type_aware_problem
from trustseek.solvers import make_solver


def midway() -> TrustModel:
    """The average of the paper's and the conservative supervisor (a third type for the benchmark)."""
    p, c = paper_model(), conservative_model()
    return trust_model(
        p.trust_levels,
        p.complexities,
        (p.initial + c.initial) / 2,
        (p.emission + c.emission) / 2,
        (p.transition + c.transition) / 2,
    )


def chain_model(K: int) -> TrustModel:
    """K trust levels from the paper's numbers: level t interpolates the emissions of low and high
    trust; after each trial trust moves one level up with the paper's P(low -> high) and one level
    down with its P(high -> low) (scaled to sum at most 1); it starts at the top."""
    p = paper_model()
    s = np.linspace(0.0, 1.0, K)
    emission = (1 - s)[None, None, :, None] * p.emission[:, :, :1] + s[None, None, :, None] * p.emission[:, :, 1:]
    up, down = p.transition[..., 0, 1], p.transition[..., 1, 0]  # [c, a, e]
    total = np.maximum(up + down, 1.0)
    up, down = up / total, down / total
    transition = np.zeros((*up.shape, K, K))
    for t in range(K):
        transition[..., t, min(t + 1, K - 1)] += up
        transition[..., t, max(t - 1, 0)] += down
        transition[..., t, t] += 1 - up - down
    initial = np.zeros(K)
    initial[-1] = 1.0
    names = tuple(f"level{t}" for t in range(K))
    return trust_model(names, p.complexities, initial, emission, transition)


def run(name: str, pomdp: AssistancePOMDP, solver: str, limit: float, **options: Any) -> float:
    t0, c0 = time.perf_counter(), time.process_time()
    policy = make_solver(solver, gap=1e-3, max_seconds=limit, **options).solve(pomdp)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    lo, up = policy.info["value_bounds_at_initial_belief"]
    label = f"{solver}" + (f" r<={options['max_resolution']}" if "max_resolution" in options else "")
    print(f"  {name:<34} {label:<14} {wall:8.2f} s wall {cpu:8.2f} s CPU   V(b0) in [{lo:.5f}, {up:.5f}]  gap {up - lo:.1e}")
    return wall


def sarsop(name: str, pomdp: AssistancePOMDP, pomdpsol: str, limit: float) -> None:
    """SARSOP on the same problem: the last row of its progress table (time, bounds, precision)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "problem.pomdpx"
        write_pomdpx(pomdp, path)
        out = subprocess.run(
            [pomdpsol, "--timeout", f"{limit:g}", "--precision", "1e-3", "--output", str(Path(tmp) / "out.policy"), str(path)],
            capture_output=True,
            text=True,
            check=False,
        ).stdout
    rows = re.findall(r"^\s*([0-9.]+)\s+\d+\s+\d+\s+(-?[0-9.]+)\s+(-?[0-9.]+)\s+([0-9.e+-]+)\s", out, re.MULTILINE)
    if not rows:
        print(f"  {name:<34} {'sarsop':<14} no progress table in pomdpsol's output:\n{out[-2000:]}")
        return
    t, lo, up, _ = rows[-1]
    print(
        f"  {name:<34} {'sarsop':<14} {float(t):8.2f} s (its clock)           V(b0) in [{lo}, {up}]  gap {float(up) - float(lo):.1e}"
    )


def curve(name: str, pomdp: AssistancePOMDP, solvers: tuple[str, ...], resolutions: tuple[int, ...], limit: float) -> None:
    """Gap against time: each solver stopped at each grid resolution (not by the clock, which a
    loaded machine stretches)."""
    for r in resolutions:
        for solver in solvers:
            run(name, pomdp, solver, 10 * limit, max_resolution=r)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="time limit 15 s per solve instead of 60 s")
    ap.add_argument("--sarsop", metavar="POMDPSOL", help="also run SARSOP's pomdpsol on the type-aware problems")
    args = ap.parse_args()
    limit = 15.0 if args.quick else 60.0
    task = paper_task()
    mixture = TypeMixture(
        ("paper", "conservative", "midway"), np.array([0.5, 0.3, 0.2]), (paper_model(), conservative_model(), midway())
    )
    print(f"type-aware solve, M = 3 types x K = 2 levels, gap 1e-3 at b0 (target < 1 s); time limit {limit:g} s")
    problem = type_aware_problem(mixture, task)
    make_solver("types", gap=1.0).solve(type_aware_problem(paper_conservative_mixture(), task))  # compile, load caches
    run("paper + conservative + midway", problem, "types", limit)
    run("paper + conservative + midway", problem, "reachable", limit)
    run("paper + conservative + midway", problem, "point", limit)
    if args.sarsop:
        sarsop("paper + conservative + midway", problem, args.sarsop, limit)
    print("  gap against time, the grid solvers stopped at a resolution:")
    curve("paper + conservative + midway", problem, ("types", "point"), (4, 8, 16), limit)
    print(f"type-aware solve, M = 2 types (paper+conservative) x K = 2 levels, gap 1e-3 at b0; time limit {limit:g} s")
    pair = type_aware_problem(paper_conservative_mixture(), task)
    run("paper + conservative", pair, "types", limit)
    run("paper + conservative", pair, "point", limit)
    if args.sarsop:
        sarsop("paper + conservative", pair, args.sarsop, limit)
    print("  gap against time, the grid solvers stopped at a resolution:")
    curve("paper + conservative", pair, ("types", "point"), (8, 16, 32, 64), limit)
    print(f"single-type models, gap 1e-3 at b0; time limit {limit:g} s")
    three = AssistancePOMDP(
        TrustModel.load(example_path("three_level_model.json")), Task.load(example_path("three_level_task.json"))
    )
    four = AssistancePOMDP(chain_model(4), task)
    for label, pomdp in (("K = 3 (three-level example)", three), ("K = 4 (chain of the paper's numbers)", four)):
        run(label, pomdp, "types", limit)
        run(label, pomdp, "reachable", limit)
        run(label, pomdp, "point", limit)


if __name__ == "__main__":
    main()
