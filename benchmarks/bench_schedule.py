"""Trial scheduling, 17 + 17 items on the paper's model, two trust levels (targets: full
control < 1 s on one core, a window of 3 items < 5 s).

Reports the grid representation (the default) and the exact alpha vectors (full control),
with the in-run baseline of the unscheduled finite horizon (a window of one item, i.e. the
paper's random order) solved the same way.
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from trustseek import AssistancePOMDP, paper_model, paper_task
from trustseek.pomdp.scheduling import SchedulingProblem
from trustseek.solvers.defaults import DEFAULT_SCHEDULE_GRID
from trustseek.solvers.scheduling import ScheduleSolver


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
    counts = (17, 17)
    rows = [
        ("window 1 (random order)", 1, "grid", 3),
        ("full control", None, "grid", 3),
        ("window 3", 3, "grid", 3),
        ("full control", None, "alpha", 1),
    ]
    times = {}
    print(f"{'problem':24} {'values':6} {'states':>7} {'time':>10} {'value':>12}")
    for label, window, rep, repeat in rows:
        problem = SchedulingProblem(pomdp, counts, window)
        solver = ScheduleSolver(representation=rep)
        t, pol = best_of(lambda s=solver, p=problem: s.solve(p), repeat)
        times[(label, rep)] = t
        print(f"{label:24} {rep:6} {pol.info['states']:7d} {t * 1000:8.1f}ms {pol.info['value']:12.6f}")
    print(f"grid: {DEFAULT_SCHEDULE_GRID} points; the alpha row is exact (bayes update)")
    for label, target in (("full control", 1.0), ("window 3", 5.0)):
        t = times[(label, "grid")]
        print(f"target: 17 + 17, {label} < {target:.0f} s -> {t:.3f} s ({'met' if t < target else 'MISSED'})")


if __name__ == "__main__":
    main()
