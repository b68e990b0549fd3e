"""Benchmark of the trust-model fit (extended Baum-Welch for the discrete IOHMM).

    python benchmarks/bench_fit.py                 # timing (1000 x 71 and 9 x 71, 10 restarts)
    python benchmarks/bench_fit.py --coverage 20   # + bootstrap CI coverage at 9 x 71 over 20 datasets

Prints iterations (E-steps) and seconds per restart, the total against the
targets (< 2 s and < 0.1 s on one core), and the speed-up of SQUAREM over plain
EM measured in the same run on the same start.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from trustseek.fit import coverage_study, paper_spec, simulate_design  # noqa: E402
from trustseek.iohmm import Structure, Workspace, encode, fit_iohmm, run_em  # noqa: E402
from trustseek.presets import paper_model  # noqa: E402


def timing(n: int, restarts: int = 10, tol: float = 1e-8, target: float | None = None) -> None:
    df = simulate_design(paper_model(), n, seed=1)
    spec = paper_spec()
    seqs = encode(df, spec)
    t0 = time.perf_counter()
    fit = fit_iohmm(seqs, spec, restarts=restarts, seed=0, tol=tol)
    total = time.perf_counter() - t0
    print(f"{n} participants x 71 trials, {restarts} restarts, tol {tol:g}")
    for i, r in enumerate(fit.runs):
        mark = " (best)" if i == fit.best else ""
        print(f"  restart {i:2d}: {r.iterations:4d} iterations, {r.seconds * 1000:8.1f} ms, log-likelihood {r.loglik:.6f}{mark}")
    its = sum(r.iterations for r in fit.runs)
    print(f"  total {total:.3f} s" + (f" (target < {target:g} s: {'met' if total < target else 'not met'})" if target else "")
          + f"; {total / its * 1000:.2f} ms per iteration")
    s = Structure(spec, seqs)
    w = Workspace(seqs, s.K, s.M, s.Ue, s.Ut)
    if fit.runs[0].seconds == fit.runs[-1].seconds and restarts > 1:  # ran batched: compare one at a time
        t1 = time.perf_counter()
        starts = [s.random(np.random.default_rng(c)) for c in np.random.SeedSequence(0).spawn(restarts)]
        for p in starts:
            run_em(s, w, p, tol=tol)
        one = time.perf_counter() - t1
        print(f"  the same restarts one at a time: {one:.3f} s; batching speed-up x{one / total:.1f}")
    # SQUAREM vs plain EM from the same start
    start = s.random(np.random.default_rng(123))
    plain = run_em(s, w, start, tol=tol, max_iter=20000, accelerate=False)
    fast = run_em(s, w, start, tol=tol, max_iter=20000, accelerate=True)
    print(f"  plain EM: {plain.iterations} iterations {plain.seconds:.3f} s; SQUAREM: {fast.iterations} iterations {fast.seconds:.3f} s; "
          f"speed-up x{plain.seconds / fast.seconds:.1f}; log-likelihoods {plain.loglik:.6f} / {fast.loglik:.6f}")


def coverage(datasets: int, bootstrap: int) -> None:
    print(f"bootstrap coverage at 9 x 71: {datasets} synthetic datasets, {bootstrap} replicates each (nominal 95%)")
    t0 = time.perf_counter()
    rows = coverage_study(paper_model(), n_participants=9, datasets=datasets, bootstrap=bootstrap, seed=0)
    print(f"  {time.perf_counter() - t0:.1f} s")
    print(f"  {'cell':66s} {'truth':>6s} {'coverage':>8s} {'width':>6s} {'mean est':>8s}")
    for r in rows:
        print(f"  {r['cell']:66s} {r['truth']:6.2f} {r['coverage']:8.2f} {r['mean_width']:6.2f} {r['mean_estimate']:8.2f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--coverage", type=int, default=0, help="number of synthetic datasets for the coverage study (0 = skip)")
    ap.add_argument("--bootstrap", type=int, default=100, help="bootstrap replicates per dataset in the coverage study")
    args = ap.parse_args(argv)
    timing(9, target=0.1)
    timing(1000, target=2.0)
    if args.coverage:
        coverage(args.coverage, args.bootstrap)
    return 0


if __name__ == "__main__":
    sys.exit(main())
