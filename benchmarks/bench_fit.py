"""Benchmark of the trust-model fit (extended Baum-Welch for the discrete IOHMM).

    python benchmarks/bench_fit.py                 # timing (9 x 71 and 1000 x 71, 10 restarts)
    python benchmarks/bench_fit.py --recovery 20   # + parameter recovery at 1000 x 71 over 20 data sets
    python benchmarks/bench_fit.py --coverage 20   # + bootstrap CI coverage at 9 x 71 over 20 data sets
    python benchmarks/bench_fit.py --big           # + 100,000 x 71: one restart on one core, 10 on 2 threads
                                                   #   (with the subsample phase and, in the same run, without)

Prints iterations (E-steps) and time per restart, the total against the targets
(< 0.1 s and < 2 s on one core) as wall time and CPU time (the machine may be
shared), the first-call time of the compiled E-step (compilation, or loading it
from the cache), and, measured in the same run: the compiled whole run
(``fit_iohmm``'s default) against the lockstep path with scipy's L-BFGS-B finish
(``compiled=False``, the previous implementation), the compiled E-step against the
numpy E-step, SQUAREM against plain EM, and 1 against 2 threads (target at
1000 x 71, 10 restarts: < 0.5 s wall on 2 cores).  With ``--big``, 100,000 x 71 (targets:
one restart < 8 s on one core, 10 restarts < 40 s on 2 cores) with the compiled run's
subsample phase (its default from 500,000 trials) and without it (``SUBSAMPLE_MIN`` raised),
per restart the E-steps on the subsample and on the whole data and how it ended.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from functools import partial
from unittest import mock

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

import trustseek.estimation.iohmm as iohmm
from trustseek.estimation import compiled_run, encode, fit_iohmm, fit_trust_model, from_model, loglik, paper_spec
from trustseek.estimation.em import run_em
from trustseek.estimation.estep import Workspace
from trustseek.estimation.options import FitOptions
from trustseek.estimation.structure import Structure
from trustseek.model.presets import paper_model
from trustseek.reproduction.coverage import coverage_study
from trustseek.simulation.designs import simulate_design


def clocks():
    return time.perf_counter(), time.process_time()


def since(t):
    return time.perf_counter() - t[0], time.process_time() - t[1]


def first_call() -> None:
    """The first E-step (the compiled one) and the first small fit (first L-BFGS-B call)."""
    seqs = encode(simulate_design(paper_model(), 2, seed=0), paper_spec())
    s = Structure(paper_spec(), seqs)
    t = clocks()
    Workspace(seqs, 2, 2, s.Ue, s.Ut).estep(s.random(np.random.default_rng(0)))
    w, c = since(t)
    t = clocks()
    fit_iohmm(seqs, paper_spec(), options=FitOptions(restarts=2, seed=0, n_jobs=1))
    w2, c2 = since(t)
    print(f"first E-step {w:.2f} s wall, {c:.2f} s CPU; first fit (2 x 71) {w2:.2f} s wall, {c2:.2f} s CPU")


def estep_speed(seqs, s, p, reps: int) -> None:
    out = {}
    for method in ("compiled", "loop"):
        w = Workspace(seqs, s.K, s.M, s.Ue, s.Ut, method=method)
        w.estep(p)
        t = clocks()
        for _ in range(reps):
            w.estep(p)
        out[method] = [x / reps for x in since(t)]
    print(
        f"  E-step: compiled {out['compiled'][0] * 1e3:.2f} ms wall / {out['compiled'][1] * 1e3:.2f} ms CPU; "
        f"numpy {out['loop'][0] * 1e3:.2f} ms wall / {out['loop'][1] * 1e3:.2f} ms CPU; "
        f"x{out['loop'][1] / out['compiled'][1]:.1f} (CPU)"
    )


def best_of(runs):
    """(wall, CPU) of the run with the least CPU time, and the median CPU time."""
    wall, cpu = min(runs, key=lambda x: x[1])
    return wall, cpu, sorted(c for _, c in runs)[len(runs) // 2]


def timing(n: int, restarts: int = 10, tol: float = 1e-8, target: float | None = None, numpy_fit: bool = False) -> None:
    df = simulate_design(paper_model(), n, seed=1)
    spec = paper_spec()
    seqs = encode(df, spec)
    fits, times = {}, {}
    for compiled in (True, False, True, False, True, False):  # interleaved, best of 3: a shared machine's noise
        t = clocks()
        fits[compiled] = fit_iohmm(
            seqs, spec, options=FitOptions(restarts=restarts, seed=0, tol=tol, n_jobs=1), compiled=compiled
        )
        times.setdefault(compiled, []).append(since(t))
    fit, old = fits[True], fits[False]
    wall, cpu, median_cpu = best_of(times[True])
    print(
        f"{n} participants x 71 trials, {restarts} restarts, tol {tol:g} (one thread; best of 3 runs; median CPU {median_cpu:.3f} s)"
    )
    for i, r in enumerate(fit.runs):
        mark = " (best)" if i == fit.best else ""
        print(
            f"  restart {i:2d}: {r.iterations:4d} iterations, {r.finishes} finishes, {r.seconds * 1000:8.1f} ms, "
            f"log-likelihood {r.loglik:.6f}, {r.ended}{mark}"
        )
    assert all(r.subsample_iterations == 0 for r in fit.runs)  # small data: the whole data from the start
    its = sum(r.iterations for r in fit.runs)
    verdict = f" (target < {target:g} s: {'met' if cpu < target else 'not met'} on CPU time)" if target else ""
    print(f"  total {wall:.3f} s wall, {cpu:.3f} s CPU{verdict}; {cpu / its * 1000:.3f} ms CPU per iteration")
    w0, c0, _ = best_of(times[False])
    its0 = sum(r.iterations for r in old.runs)
    print(
        f"  lockstep path with L-BFGS-B (compiled=False): {w0:.3f} s wall, {c0:.3f} s CPU, {its0} E-steps; "
        f"compiled run x{c0 / cpu:.1f} (CPU), {its} E-steps; best log-likelihood {fit.loglik:.9f} vs {old.loglik:.9f} "
        f"(difference {fit.loglik - old.loglik:+.1e}); every start at least as high: "
        f"{all(a.loglik >= b.loglik - 1e-9 * abs(b.loglik) for a, b in zip(fit.runs, old.runs, strict=True))}"
    )
    s = Structure(spec, seqs)
    p = s.random(np.random.default_rng(0))
    estep_speed(seqs, s, p, reps=max(5, min(200, 20000 // n)))
    if numpy_fit:  # the same fit with the numpy E-step (the previous implementation)
        with mock.patch.object(iohmm, "Workspace", partial(Workspace, method="loop")):
            t = clocks()
            ref = fit_iohmm(seqs, spec, options=FitOptions(restarts=restarts, seed=0, tol=tol, n_jobs=1))
            w2, c2 = since(t)
        print(
            f"  numpy E-step fit: {w2:.3f} s wall, {c2:.3f} s CPU; compiled x{c2 / cpu:.1f} (CPU); "
            f"same best log-likelihood: {abs(ref.loglik - fit.loglik) < 1e-6}"
        )
    if n >= 1000:  # the starts over 2 threads, against 1 thread in the same run
        walls, cpus = {}, {}
        for jobs, compiled in ((1, True), (2, True), (2, False)) * 3:
            t = clocks()
            two = fit_iohmm(seqs, spec, options=FitOptions(restarts=restarts, seed=0, tol=tol, n_jobs=jobs), compiled=compiled)
            w_, c_ = since(t)
            walls[jobs, compiled] = min(walls.get((jobs, compiled), w_), w_)
            cpus[jobs, compiled] = min(cpus.get((jobs, compiled), c_), c_)
            assert two.loglik == (fit if compiled else old).loglik  # the same numbers whatever the threads
        w1, w2 = walls[1, True], walls[2, True]
        print(
            f"  threads: 1 thread {w1:.3f} s wall, 2 threads {w2:.3f} s wall ({cpus[2, True]:.3f} s CPU): x{w1 / w2:.2f} "
            f"(target 10 restarts < 0.5 s on 2 cores: {'met' if w2 < 0.5 else 'not met'}); same log-likelihood; "
            f"lockstep path on 2 threads {walls[2, False]:.3f} s wall ({cpus[2, False]:.3f} s CPU)"
        )
    # SQUAREM vs plain EM from the same start
    w = Workspace(seqs, s.K, s.M, s.Ue, s.Ut)
    start = s.random(np.random.default_rng(123))
    (plain,) = run_em(s, w, [start], tol=tol, max_iter=20000, accelerate=False)
    (fast,) = run_em(s, w, [start], tol=tol, max_iter=20000, accelerate=True)
    print(
        f"  plain EM: {plain.iterations} iterations {plain.seconds:.3f} s; "
        f"SQUAREM: {fast.iterations} iterations {fast.seconds:.3f} s; "
        f"speed-up x{plain.seconds / fast.seconds:.1f}; log-likelihoods {plain.loglik:.6f} / {fast.loglik:.6f}"
    )


def big(n: int = 100_000) -> None:
    """100,000 x 71: one restart on one core (target < 8 s), 10 restarts on 2 threads (target < 40 s),
    with the subsample phase (the default) and without it, in the same run."""
    spec = paper_spec()
    t = clocks()
    seqs = encode(simulate_design(paper_model(), n, seed=1), spec)
    w, c = since(t)
    print(f"{n} x 71: simulated and encoded in {w:.1f} s wall; load average {os.getloadavg()[0]:.1f}")
    default_min = compiled_run.SUBSAMPLE_MIN
    best = {}
    for restarts, jobs, target in ((1, 1, 8.0), (10, 2, 40.0)):
        for phase in (True, False):
            compiled_run.SUBSAMPLE_MIN = default_min if phase else 10**15
            try:
                t = clocks()
                fit = fit_iohmm(seqs, spec, options=FitOptions(restarts=restarts, seed=0, n_jobs=jobs))
                w, c = since(t)
            finally:
                compiled_run.SUBSAMPLE_MIN = default_min
            its = sum(r.iterations for r in fit.runs)
            sub = sum(r.subsample_iterations for r in fit.runs)
            name = "subsample phase" if phase else "whole data only (before)"
            print(
                f"  {restarts} restart(s), {jobs} thread(s), {name}: {w:.1f} s wall, {c:.1f} s CPU, {its} E-steps on the "
                f"whole data + {sub} on a tenth, log-likelihood {fit.loglik:.9f} "
                f"(target < {target:g} s wall: {'met' if w < target else 'not met'}); load {os.getloadavg()[0]:.1f}"
            )
            for i, r in enumerate(fit.runs):
                print(
                    f"    restart {i}: {r.subsample_iterations:3d} + {r.iterations:3d} E-steps, {r.finishes} finishes, "
                    f"{r.seconds:5.1f} s, log-likelihood {r.loglik:.9f}, {r.ended}"
                )
            best[restarts, phase] = fit.loglik
        d = (best[restarts, True] - best[restarts, False]) / abs(best[restarts, False])
        print(f"  best maximum with against without the subsample phase: {d:+.1e} relative")


def recovery(datasets: int, n: int = 1000, restarts: int = 10) -> None:
    """MAE over the free cells on ``datasets`` synthetic data sets (seeds 0..datasets-1), and per cell."""
    truth = paper_model()
    spec, ptrue = from_model(truth)
    print(f"parameter recovery at {n} x 71, {restarts} restarts, data set seeds 0..{datasets - 1}")
    maes, errs, events, lr = [], {}, {}, []
    t = clocks()
    for d in range(datasets):
        res = fit_trust_model(simulate_design(truth, n, seed=d), options=FitOptions(restarts=restarts, seed=0))
        e = []
        for c in res.cells():
            x = c["estimate"] - float(getattr(truth, c["table"])[tuple(c["index"])])
            e.append(abs(x))
            errs.setdefault(c["cell"], []).append(x)
            events.setdefault(c["cell"], []).append(c["events"])
        maes.append(float(np.mean(e)))
        lr.append(2 * (res.loglik - loglik(res.seqs, spec, ptrue)))
        print(
            f"  seed {d:3d}: MAE {maes[-1]:.4f}; 2 (LL(fit) - LL(truth)) = {lr[-1]:6.2f}; restarts end in "
            f"[{min(res.restart_logliks):.2f}, {max(res.restart_logliks):.2f}]"
        )
    wall, cpu = since(t)
    q = np.quantile(maes, [0, 0.5, 0.9, 1])
    print(
        f"  MAE min {q[0]:.4f}, median {q[1]:.4f}, 90% {q[2]:.4f}, max {q[3]:.4f}; <= 0.03 on "
        f"{sum(m <= 0.03 for m in maes)} of {datasets}; LL(fit) >= LL(truth) on {sum(x >= 0 for x in lr)} of {datasets} "
        f"({wall:.1f} s wall, {cpu:.1f} s CPU)"
    )
    print(f"  {'cell':62s} {'RMSE':>6s} {'max|err|':>8s} {'events':>7s}")
    for k, v in errs.items():
        v = np.asarray(v)
        print(f"  {k:62s} {np.sqrt(np.mean(v * v)):6.3f} {np.abs(v).max():8.3f} {np.mean(events[k]):7.0f}")


def coverage(datasets: int, bootstrap: int) -> None:
    print(f"bootstrap coverage at 9 x 71: {datasets} synthetic datasets, {bootstrap} replicates each (nominal 95%)")
    t0 = time.perf_counter()
    rows = coverage_study(paper_model(), n_participants=9, datasets=datasets, bootstrap=bootstrap, seed=0)
    print(f"  {time.perf_counter() - t0:.1f} s")
    print(
        f"  {'cell':66s} {'truth':>6s} {'coverage':>8s} {'width':>6s} {'mean est':>8s} {'at 0/1':>6s} {'coverage':>8s} {'LR':>3s}"
    )
    for r in rows:
        print(
            f"  {r['cell']:66s} {r['truth']:6.2f} {r['coverage']:8.2f} {r['mean_width']:6.2f} {r['mean_estimate']:8.2f} "
            f"{r['at_boundary']:6d} {r['boundary_coverage']:8.2f} {r['likelihood']:3d}"
        )
    print(
        "  at 0/1: data sets whose estimate of the cell is at the boundary; their coverage; LR: of them, likelihood-ratio intervals"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--recovery", type=int, default=0, help="number of synthetic datasets for the recovery study at 1000 x 71 (0 = skip)"
    )
    ap.add_argument("--coverage", type=int, default=0, help="number of synthetic datasets for the coverage study (0 = skip)")
    ap.add_argument("--bootstrap", type=int, default=100, help="bootstrap replicates per dataset in the coverage study")
    ap.add_argument("--big", action="store_true", help="also time 100,000 participants x 71 trials")
    args = ap.parse_args(argv)
    first_call()
    timing(9, target=0.1, numpy_fit=True)
    timing(1000, target=2.0)
    if args.big:
        big()
    if args.recovery:
        recovery(args.recovery)
    if args.coverage:
        coverage(args.coverage, args.bootstrap)
    return 0


if __name__ == "__main__":
    sys.exit(main())
