"""Simulator throughput: trials per second on one core, paper model, trust-aware policy.

The simulator (``trustseek.simulate``: its compiled kernel for the common cases, built with the
package) is compared
with its own numpy loop (``compiled=False``, vectorized over participants, the reference the
kernel is tested against) and two plain per-trial Python loops, measured in the same run on
the same model and policy; and, at the design study's size (9 participants x 71 trials under
the randomized policy, where the numpy loop's per-trial overhead dominates), the time of one
simulation both ways.  The plain loops:

* ``core loop``: one participant and one trial at a time through the core API
  (``PolicyRunner.decide`` / ``observe``), sampling with a numpy Generator;
* ``tight loop``: the same dynamics written as a bare Python loop over lists, with
  ``random.random()`` and the policy's threshold (the fastest plain loop we could write).

    python benchmarks/bench_simulate.py            # 1,000,000 participants x 71 trials
    python benchmarks/bench_simulate.py 200000     # fewer participants
"""

from __future__ import annotations

import os
import random
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from trustseek import PolicyRunner, paper_model, paper_task, randomized, solve
from trustseek.policies import ask_bounds
from trustseek.simulation import simulate
from trustseek.vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS

COUNTS = (41, 30)  # Section V: 71 trials, 41 low and 30 high


def core_loop(model, task, policy, n_participants: int, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    total = 0.0
    R = task.reward_table()
    for _ in range(n_participants):
        runner = PolicyRunner(policy, rng=rng)
        trust = int(rng.random() < model.initial[1])
        sched = rng.permutation(np.repeat([0, 1], COUNTS))
        for c in sched:
            a = ACTIONS.index(runner.decide(int(c)))
            o = 0 if rng.random() < model.emission[c, a, trust, 0] else 1
            p_rel = task.p_experience(int(c), a, o)[1]
            e = int(rng.random() < p_rel)
            total += R[a, o, e]
            trust = int(rng.random() < model.transition[c, a, e, trust, 1])
            runner.observe(int(c), ACTIONS[a], HUMAN_ACTIONS[o], EXPERIENCES[e])
    return total


def tight_loop(model, task, policy, n_participants: int, seed: int = 0) -> float:
    r = random.Random(seed)
    th = ask_bounds(policy).tolist()
    em = model.emission[..., 0].tolist()  # [c][a][t] P(intervene)
    tr = model.transition[..., 1].tolist()  # [c][a][e][t] P(T' = high)
    a0 = model.transition[..., 0, 1].tolist()
    slope = (model.transition[..., 1, 1] - model.transition[..., 0, 1]).tolist()
    prel = task.experience_table()[..., 1].tolist()  # [c][a][o]
    R = task.reward_table().tolist()
    base = [0] * COUNTS[0] + [1] * COUNTS[1]
    total = 0.0
    for _ in range(n_participants):
        x = float(model.initial[1])
        trust = 1 if r.random() < x else 0
        sched = base[:]
        r.shuffle(sched)
        for c in sched:
            a = 1 if x < th[c] else 0
            o = 0 if r.random() < em[c][a][trust] else 1
            e = 1 if r.random() < prel[c][a][o] else 0
            total += R[a][o][e]
            trust = 1 if r.random() < tr[c][a][e][trust] else 0
            x = a0[c][a][e] + slope[c][a][e] * x  # eq. (3)
    return total


def rate(fn, trials: int) -> tuple[float, float]:
    """Trials per CPU-second of this process (one core; robust to other load on the machine)
    and the wall time."""
    w0, c0 = time.perf_counter(), time.process_time()
    fn()
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    return trials / cpu, wall


def small(reps: int = 300) -> None:
    """One recorded simulation at the design study's size, compiled and numpy loop."""
    model, task = paper_model(), paper_task()
    ask = randomized({"low": 0.1, "high": 0.4})
    for compiled in (True, False):
        simulate(model, task, ask, 9, counts=COUNTS, seed=0, compiled=compiled)  # warm-up
        c = time.process_time()
        for r in range(reps):
            simulate(model, task, ask, 9, counts=COUNTS, seed=r, compiled=compiled)
        ms = 1000 * (time.process_time() - c) / reps
        print(
            f"  9 participants x 71 trials, recorded, {'compiled  ' if compiled else 'numpy loop'}: {ms:6.2f} ms CPU per simulation"
        )


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    n = int(argv[0]) if argv else 1_000_000
    model, task = paper_model(), paper_task()
    T = sum(COUNTS)
    print(
        f"paper model, {COUNTS[0]} low + {COUNTS[1]} high trials per participant, one core (rates per CPU-second of this process)"
    )
    results = {}
    for update in ("paper", "bayes"):
        policy = solve(model, task, belief_update=update)
        simulate(model, task, policy, 2000, counts=COUNTS, seed=0, record=False)  # warm-up
        vec, dt = rate(lambda policy=policy: simulate(model, task, policy, n, counts=COUNTS, seed=1, record=False), n * T)
        rec_n = min(n, 200_000)
        vec_rec, dt_rec = rate(
            lambda policy=policy, rec_n=rec_n: simulate(model, task, policy, rec_n, counts=COUNTS, seed=1, record=True), rec_n * T
        )
        loop_n = min(n, 200_000)
        loop, _ = rate(
            lambda policy=policy, loop_n=loop_n: simulate(
                model, task, policy, loop_n, counts=COUNTS, seed=1, record=False, compiled=False
            ),
            loop_n * T,
        )
        results[update] = (vec, vec_rec, n, dt, rec_n, dt_rec, loop)
    policy = solve(model, task, belief_update="paper")
    core, _ = rate(lambda: core_loop(model, task, policy, 60), 60 * T)
    tight, _ = rate(lambda: tight_loop(model, task, policy, 3000), 3000 * T)
    print(f"  core loop (PolicyRunner per trial)      {core / 1e6:10.4f} M trials/s")
    print(f"  tight loop (plain Python, eq. 3)         {tight / 1e6:10.4f} M trials/s")
    for update, (vec, vec_rec, n_, dt, rec_n, dt_rec, loop) in results.items():
        print(
            f"  vectorized, trust-aware ({update:5s} belief) {vec / 1e6:10.2f} M trials/s "
            f"({n_:,} participants, {dt:.2f} s wall)  = {vec / tight:6.0f}x tight loop, {vec / core:8.0f}x core loop"
        )
        print(
            f"  vectorized, recording every trial ({update:5s}) {vec_rec / 1e6:7.2f} M trials/s "
            f"({rec_n:,} participants, {dt_rec:.2f} s wall)"
        )
        print(f"  numpy loop (compiled=False, {update:5s})      {loop / 1e6:10.2f} M trials/s (same run)")
    small()
    best = results["paper"][0]
    print(f"target >= 10 M trials/s: {'met' if best >= 10e6 else 'NOT met'} ({best / 1e6:.1f} M trials/s)")


if __name__ == "__main__":
    main()
