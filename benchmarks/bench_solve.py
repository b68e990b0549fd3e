"""Solve time of the paper preset on the belief grid (target: < 100 ms for 10,001 points).

Reports policy iteration (the default) against plain value iteration to the same
certified tolerance, measured in the same run, for the default grid and 10,001 points.
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from trustseek import AssistancePOMDP, GridSolver, paper_model, paper_task
from trustseek.solvers.defaults import DEFAULT_GRID


def best_of(fn, repeat):
    best = float("inf")
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    pomdp = AssistancePOMDP(paper_model(), paper_task())
    print(f"{'update':7} {'grid':>6} {'method':18} {'time':>10} {'iters':>6} {'threshold':>10} {'residual':>9}  speed-up")
    for update in ("bayes", "paper"):
        for grid in (DEFAULT_GRID, 10_001):
            pi = GridSolver(grid=grid, belief_update=update)
            vi_solver = GridSolver(grid=grid, belief_update=update, method="value-iteration")
            t_pi, pol = best_of(lambda s=pi: s.solve(pomdp), 5)
            t_vi, vi = best_of(lambda s=vi_solver: s.solve(pomdp), 1)
            for name, t, p in (("value-iteration", t_vi, vi), ("policy-iteration", t_pi, pol)):
                print(
                    f"{update:7} {grid:6d} {name:18} {t * 1000:8.1f}ms {p.info['iterations']:6d} "
                    f"{p.thresholds()['high']:10.5f} {p.info['bellman_residual']:9.1e}  "
                    + (f"{t_vi / t_pi:6.1f}x" if name == "policy-iteration" else "(baseline)")
                )
    target = 0.100
    t, _ = best_of(lambda: GridSolver(grid=10_001).solve(pomdp), 5)
    print(f"target: 10,001-point solve < {target * 1000:.0f} ms -> {t * 1000:.1f} ms ({'met' if t < target else 'MISSED'})")


if __name__ == "__main__":
    main()
