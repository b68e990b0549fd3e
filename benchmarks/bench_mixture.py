"""Benchmark of the supervisor-type fit (mixture IOHMM) and the acceptance figures of the types.

    python benchmarks/bench_mixture.py               # timing: M = 3 types, 1000 x 71, 10 restarts, one core
    python benchmarks/bench_mixture.py --acceptance  # + 200 x 71 of paper + conservative (50 %): recovery, selection

Timing: the pooled fit of the same data (10 restarts, the same tolerance) is the in-run
baseline; the target is < 5 s on one core for the mixture.  Data: ``simulate_design`` of
``paper_conservative_mixture(0.5)`` (two types; fitting three shows the cost of a type
the data do not need).  Acceptance: share of participants whose most probable type is
their true type, the fit's log-likelihood against the generating mixture's, and the
number of types chosen by BIC and by the 5-fold participant-held-out log-likelihood on
that population and on the paper's model alone.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from trustseek.estimation import encode, fit_iohmm, paper_spec
from trustseek.estimation.mixture import fit_mixture, mixture_loglik
from trustseek.estimation.options import FitOptions
from trustseek.estimation.selection import select_types
from trustseek.model.presets import paper_conservative_mixture, paper_model
from trustseek.simulation.designs import simulate_design
from trustseek.simulation.populations import Supervisors


def clocks():
    return time.perf_counter(), time.process_time()


def since(t):
    return time.perf_counter() - t[0], time.process_time() - t[1]


def population(n: int, seed: int):
    mix = paper_conservative_mixture(0.5)
    sup = Supervisors.from_mixture(mix, n, rng=seed)
    return mix, sup, simulate_design(sup, n, seed=seed + 1)


def timing(n: int = 1000, types: int = 3, restarts: int = 10, tol: float = 1e-8, target: float = 5.0) -> None:
    spec = paper_spec()
    _mix, _sup, df = population(n, 1)
    seqs = encode(df, spec)
    fit_mixture(
        encode(df.head(71 * 3), spec), spec, 2, options=FitOptions(restarts=1, max_iter=5, n_jobs=1)
    )  # load the compiled passes
    t = clocks()
    pooled = fit_iohmm(seqs, spec, options=FitOptions(restarts=restarts, seed=0, tol=tol, n_jobs=1))
    pw, pc = since(t)
    print(f"{n} participants x 71 trials (paper + conservative, 50 %), tol {tol:g}, one thread")
    print(f"  pooled fit, {restarts} restarts: {pw:.3f} s wall, {pc:.3f} s CPU; log-likelihood {pooled.loglik:.4f}")
    t = clocks()
    fit = fit_mixture(seqs, spec, types, options=FitOptions(restarts=restarts, seed=0, tol=tol, n_jobs=1), pooled=pooled.params)
    w, c = since(t)
    its = sum(r.iterations for r in fit.runs)
    for i, r in enumerate(fit.runs):
        mark = " (best)" if i == fit.best else ""
        print(f"  start {i:2d}: {r.iterations:4d} E-steps, {r.finishes} finishes, log-likelihood {r.loglik:.4f}, {r.ended}{mark}")
    verdict = "met" if c < target else "not met"
    print(
        f"  mixture fit, M = {types}, {restarts} restarts: {w:.3f} s wall, {c:.3f} s CPU (target < {target:g} s: {verdict} "
        f"on CPU time); x{c / pc:.1f} the pooled fit; {c / its * 1000:.2f} ms CPU per E-step ({its} E-steps); "
        f"weights {np.round(fit.weights, 3).tolist()}"
    )


def acceptance(n: int = 200) -> None:
    spec = paper_spec()
    mix, sup, df = population(n, 11)
    seqs = encode(df, spec)
    t = clocks()
    fit = fit_mixture(seqs, spec, 2, options=FitOptions(restarts=10, seed=0, n_jobs=1))
    _w, c = since(t)
    truth = np.where(sup.index == mix.type_index("conservative"), 0, 1)  # type1 relies least
    right = float((fit.type_posteriors().argmax(1) == truth).mean())
    true_ll = mixture_loglik(seqs, mix)
    print(f"acceptance: {n} x 71 of paper + conservative (50 %), M = 2, 10 restarts ({c:.2f} s CPU)")
    print(
        f"  right type by maximum posterior: {right:.1%} (target >= 90 %); log-likelihood {fit.loglik:.3f} vs the "
        f"generating mixture's {true_ll:.3f} ({'>=' if fit.loglik >= true_ll else '<'}); weights "
        f"{np.round(fit.weights, 3).tolist()}"
    )
    for label, data in (("paper + conservative", df), ("paper model alone", simulate_design(paper_model(), n, seed=12))):
        t = clocks()
        rows = select_types(data, types=(1, 2, 3), folds=5, options=FitOptions(restarts=10, seed=0, tol=1e-6, n_jobs=1))
        _w, c = since(t)
        bic = next(r["types"] for r in rows if r["best_bic"])
        held = next(r["types"] for r in rows if r["best_heldout"])
        print(f"  selection on {label} ({c:.1f} s CPU): BIC picks M = {bic}, held-out picks M = {held}")
        for r in rows:
            print(
                f"    M = {r['types']}: log-likelihood {r['loglik']:.3f} ({r['reached_best']} of {r['starts']} starts), "
                f"BIC {r['bic']:.1f}, held-out {r['heldout_loglik']:.3f}"
            )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--acceptance", action="store_true", help="also the acceptance figures at 200 x 71")
    ap.add_argument("-n", type=int, default=1000)
    args = ap.parse_args()
    print(f"load: {os.getloadavg()[0]:.2f} (1 min)")
    timing(args.n)
    if args.acceptance:
        acceptance()


if __name__ == "__main__":
    main()
