"""Benchmark of the design study (``trustseek design``).

    python benchmarks/bench_design.py              # all figures
    python benchmarks/bench_design.py --quick      # fewer replicates
    python benchmarks/bench_design.py --replicate  # only the stages of one replicate

Prints, per stage, the time of one replicate at the paper's size (9 x 71: simulate experiment 1,
fit, solve, exact evaluation, experiment 2 with its tests) and the replicates per second on one
core (target: > 50, i.e. < 20 ms per replicate); the effect of the fit's restarts on the regret
(the same replicates fitted with 1, 2 and 10 restarts: mean regret and the mean paired
difference to 10 restarts); the default sweep's time with 2 local processes (target: < 5
minutes); and a Dask LocalCluster with 2 workers against 1 worker on the same sweep (target:
>= 1.8x), after checking that both give the same summary.
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from trustseek.design import DesignConfig, FitSettings, run_design
from trustseek.design.evaluation import evaluate_policy
from trustseek.design.replicate import _agnostic, paired_tests, plan, replicate_seed, run_replicate
from trustseek.design.sweep import study_of
from trustseek.estimation.fit import fit_trust_model
from trustseek.policies import randomized
from trustseek.simulation import crossover, simulate
from trustseek.vocab import TRIAL_COLUMNS


def stages(cfg: DesignConfig, n: int) -> None:
    """Time of each stage of one replicate, averaged over ``n`` replicates."""
    study = study_of(cfg)
    design = cfg.designs()[0]
    truth, task, fs = study.truth, study.task, study.fit
    t = dict.fromkeys(("experiment 1", "fit", "solve", "agnostic", "exact evaluation", "experiment 2 + tests"), 0.0)
    run_replicate(study, 0, design, 0)  # compile / warm up
    for r in range(n):
        s1, _, s2 = replicate_seed(cfg.seed, 0, r).spawn(3)
        c = time.perf_counter()
        ask = randomized({"low": design.ask_low, "high": design.ask_high})
        frame = simulate(truth, task, ask, design.participants, counts=design.counts, seed=s1).trials()[list(TRIAL_COLUMNS)]
        t["experiment 1"] += time.perf_counter() - c
        c = time.perf_counter()
        fit = fit_trust_model(frame, restarts=fs.restarts, seed=r, tol=fs.tol, n_jobs=1)
        t["fit"] += time.perf_counter() - c
        c = time.perf_counter()
        aware = plan(fit.model, task, fs)
        t["solve"] += time.perf_counter() - c
        c = time.perf_counter()
        agn = _agnostic(frame, task)
        t["agnostic"] += time.perf_counter() - c
        c = time.perf_counter()
        evaluate_policy(aware, truth, task, grid=fs.evaluation_grid)
        t["exact evaluation"] += time.perf_counter() - c
        c = time.perf_counter()
        sim = crossover(truth, task, [aware, agn], max(cfg.participants_2), seed=s2, record=False, belief_model=fit.model)
        rr = sim.summary_arrays["cumulative_reward"]
        for k in cfg.participants_2:
            paired_tests(rr[:k, 0], rr[:k, 1])
        t["experiment 2 + tests"] += time.perf_counter() - c
    total = sum(t.values())
    print(f"one replicate at 9 x 71 ({fs.restarts} restart(s)), mean of {n}:")
    for k, v in t.items():
        print(f"  {k:22s} {1000 * v / n:7.1f} ms")
    print(f"  {'total':22s} {1000 * total / n:7.1f} ms  (target < 20 ms)")
    c = time.perf_counter()
    for r in range(n):
        run_replicate(study, 0, design, r)
    dt = time.perf_counter() - c
    print(f"replicates per second on one core: {n / dt:.1f} ({1000 * dt / n:.1f} ms each)")


def restarts_effect(cfg: DesignConfig, n: int) -> None:
    """Mean regret of the same replicates (same data) fitted with 1, 2 and 10 restarts."""
    regrets = {}
    for restarts in (1, 2, 10):
        c = DesignConfig(**{**cfg.__dict__, "fit": FitSettings(restarts=restarts), "replicates": n, "participants_2": (5,)})
        study = study_of(c)
        d = c.designs()[0]
        t0 = time.perf_counter()
        regrets[restarts] = np.array([run_replicate(study, 0, d, r).get("regret", np.nan) for r in range(n)])
        dt = time.perf_counter() - t0
        print(f"  {restarts:2d} restarts: mean regret {np.nanmean(regrets[restarts]):.4f} ({1000 * dt / n:.0f} ms per replicate)")
    for restarts in (1, 2):
        d = regrets[restarts] - regrets[10]
        se = np.nanstd(d, ddof=1) / np.sqrt(np.sum(np.isfinite(d)))
        print(
            f"  {restarts} vs 10 restarts: mean paired regret difference {np.nanmean(d):+.4f} ± {1.96 * se:.4f}; "
            f"identical fits in {np.mean(np.abs(d) < 1e-9):.0%} of replicates"
        )


def default_sweep() -> None:
    cfg = DesignConfig()
    t0 = time.perf_counter()
    run_design(cfg, jobs=2)
    dt = time.perf_counter() - t0
    print(f"default sweep ({cfg.replicates} replicates, 2 local processes): {dt:.1f} s (target < 300 s)")


def dask_speedup(replicates: int) -> None:
    from distributed import Client, LocalCluster

    cfg = DesignConfig(replicates=replicates)
    times, summaries, cpu = {}, {}, {}
    for workers in (1, 2):
        with (
            LocalCluster(n_workers=workers, processes=True, threads_per_worker=1, host="127.0.0.1", dashboard_address=None) as cl,
            Client(cl) as client,
        ):
            run_design(DesignConfig(replicates=2 * workers), client=client)  # warm up (compile in every worker)
            cpu0 = sum(client.run(time.process_time).values())
            t0 = time.perf_counter()
            res = run_design(cfg, client=client)
            times[workers] = time.perf_counter() - t0
            cpu[workers] = sum(client.run(time.process_time).values()) - cpu0
            summaries[workers] = json.dumps(res.summary, sort_keys=True)
    same = summaries[1] == summaries[2]
    print(
        f"LocalCluster, {replicates} replicates: 1 worker {times[1]:.1f} s, 2 workers {times[2]:.1f} s, "
        f"speed-up {times[1] / times[2]:.2f}x (target >= 1.8x); same summary: {same}"
    )
    # on a shared machine the wall-clock speed-up is bounded by the CPU the workers get
    print(
        f"  workers' CPU time: 1 worker {cpu[1]:.1f} s, 2 workers {cpu[2]:.1f} s in all; "
        f"CPU share per worker of the wall time: {cpu[1] / times[1]:.2f} and {cpu[2] / (2 * times[2]):.2f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--dask-only", action="store_true", help="only the LocalCluster speed-up")
    ap.add_argument("--replicate", action="store_true", help="only the stages of one replicate")
    args = ap.parse_args()
    if args.replicate:
        stages(DesignConfig(), 10 if args.quick else 40)
        return
    if args.dask_only:
        dask_speedup(20 if args.quick else 100)
        return
    n = 10 if args.quick else 40
    cfg = DesignConfig()
    stages(cfg, n)
    print("effect of the fit's restarts on the regret (same data):")
    restarts_effect(cfg, 10 if args.quick else 60)
    default_sweep()
    dask_speedup(20 if args.quick else 100)


if __name__ == "__main__":
    main()
