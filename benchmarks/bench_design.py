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
from trustseek.design.replicate import (
    agnostic_of,
    experiment1_sequences,
    fit_encoded,
    paired_tests,
    replicate_seed,
    run_replicate,
)
from trustseek.design.sweep import study_of
from trustseek.estimation import fit as fit_module
from trustseek.estimation.fit import fit_trust_model
from trustseek.estimation.options import FitOptions
from trustseek.estimation.sequences import encode
from trustseek.estimation.trust_iohmm import preset_spec
from trustseek.policies import randomized
from trustseek.reproduction.robustness import solve_policy
from trustseek.simulation import crossover, simulate
from trustseek.vocab import TRIAL_COLUMNS


def stages(cfg: DesignConfig, n: int) -> None:
    """CPU time of each stage of one replicate, averaged over ``n`` replicates, with the fit as the
    replicate runs it and, in the same run (after the stages), as before (fit_trust_model on the
    lockstep path)."""
    study = study_of(cfg)
    design = cfg.designs()[0]
    truth, task, fs = study.truth, study.task, study.fit
    names = ("experiment 1", "fit", "solve", "agnostic", "exact evaluation", "experiment 2 + tests")
    t = dict.fromkeys(names, 0.0)
    before = 0.0
    run_replicate(study, 0, design, 0)  # compile / warm up
    lockstep = fit_module.fit_iohmm

    def old_fit(frame, r):
        fit_module.fit_iohmm = lambda *a, **k: lockstep(*a, **k, compiled=False)
        try:
            return fit_trust_model(frame, options=FitOptions(restarts=fs.restarts, seed=r, tol=fs.tol, n_jobs=1))
        finally:
            fit_module.fit_iohmm = lockstep

    old_fit(simulate(truth, task, randomized({"low": 0.1, "high": 0.4}), 2, counts=design.counts, seed=0).trials(), 0)
    frames = []
    for r in range(n):
        s1, _, s2 = replicate_seed(cfg.seed, 0, r).spawn(3)
        c = time.process_time()
        ask = randomized({"low": design.ask_low, "high": design.ask_high})
        sim1 = simulate(truth, task, ask, design.participants, counts=design.counts, seed=s1)
        seqs, spec = experiment1_sequences(sim1)
        t["experiment 1"] += time.process_time() - c
        c = time.process_time()
        model = fit_encoded(seqs, spec, fs, r)
        t["fit"] += time.process_time() - c
        c = time.process_time()
        aware = solve_policy(model, task, fs.belief_update, fs.grid)
        t["solve"] += time.process_time() - c
        c = time.process_time()
        agn = agnostic_of(sim1)
        t["agnostic"] += time.process_time() - c
        c = time.process_time()
        evaluate_policy(aware, truth, task, grid=fs.evaluation_grid)
        evaluate_policy(agn, truth, task, grid=fs.evaluation_grid)
        t["exact evaluation"] += time.process_time() - c
        c = time.process_time()
        sim = crossover(truth, task, [aware, agn], max(cfg.participants_2), seed=s2, record=False, belief_model=model)
        rr = sim.summary_arrays["cumulative_reward"]
        for k in cfg.participants_2:
            paired_tests(rr[:k, 0], rr[:k, 1])
        t["experiment 2 + tests"] += time.process_time() - c
        frames.append((sim1.trials()[list(TRIAL_COLUMNS)], s1, s2, model, aware, agn))
    # as before, apart from the stages (whose caches they would evict): the fit, and experiment 1
    # and 2 through the numpy loop (compiled=False), experiment 1 with its trial log and encode()
    exp1_before = exp2_before = 0.0
    for r, (frame, s1, s2, model, aware, agn) in enumerate(frames):
        c = time.process_time()
        old_fit(frame, r)
        before += time.process_time() - c
        c = time.process_time()
        ask = randomized({"low": design.ask_low, "high": design.ask_high})
        f1 = simulate(truth, task, ask, design.participants, counts=design.counts, seed=s1, compiled=False).trials()
        f1 = f1[list(TRIAL_COLUMNS)]
        encode(f1, preset_spec("paper", f1))
        exp1_before += time.process_time() - c
        c = time.process_time()
        sim = crossover(
            truth, task, [aware, agn], max(cfg.participants_2), seed=s2, record=False, belief_model=model, compiled=False
        )
        rr = sim.summary_arrays["cumulative_reward"]
        for k in cfg.participants_2:
            paired_tests(rr[:k, 0], rr[:k, 1])
        exp2_before += time.process_time() - c
    total = sum(t.values())
    print(f"one replicate at 9 x 71 ({fs.restarts} restart(s)), mean CPU time of {n}:")
    for k, v in t.items():
        print(f"  {k:22s} {1000 * v / n:7.1f} ms")
    print(f"  {'total':22s} {1000 * total / n:7.1f} ms  (target < 20 ms)")
    print(f"  fit as before (fit_trust_model, lockstep path with L-BFGS-B): {1000 * before / n:.1f} ms")
    print(f"  experiment 1 through the numpy loop, its trial log and encode(): {1000 * exp1_before / n:.1f} ms")
    print(f"  experiment 2 + tests, the simulation through the numpy loop: {1000 * exp2_before / n:.1f} ms")
    c, w = time.process_time(), time.perf_counter()
    for r in range(n):
        run_replicate(study, 0, design, r)
    dt, wall = time.process_time() - c, time.perf_counter() - w
    print(
        f"run_replicate: {1000 * dt / n:.1f} ms CPU, {1000 * wall / n:.1f} ms wall each; "
        f"replicates per second on one core: {n / dt:.1f} by CPU time (target > 50)"
    )


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
