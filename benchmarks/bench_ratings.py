"""Benchmark of the joint fit on human actions and self-reported ratings (``fit --rating``).

    python benchmarks/bench_ratings.py             # 1000 participants x 20 trials
    python benchmarks/bench_ratings.py --quick     # 300 participants

Simulates the paper model with a 5-level rating table (the paper's design, 10 + 10 trials per
participant, the randomized policy), ratings on every trial and on every 5th, and fits
(10 random starts): the joint model, the same log without its ratings (the in-run baseline),
and the ratings alone.  Prints per fit the mean absolute error over the estimated cells
against the generating model (target for the joint fit: <= 0.03), the largest error, the
mean absolute error over the cells of the action model alone (initial, emission, transition),
the log-likelihood and the time.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from trustseek.estimation.fit import fit_trust_model
from trustseek.estimation.options import FitOptions
from trustseek.estimation.result import FitResult
from trustseek.model import RatingTable, TrustModel, paper_model
from trustseek.simulation import simulate_design

RATING = RatingTable(("1", "2", "3", "4", "5"), np.array([[0.35, 0.30, 0.20, 0.10, 0.05], [0.05, 0.10, 0.20, 0.30, 0.35]]))


def errors(result: FitResult, truth: TrustModel, actions_only: bool = False) -> np.ndarray:
    """Absolute error of every estimated cell of ``result`` against ``truth`` (without the rating cells)."""
    out = []
    for c in result.cells():
        if actions_only and c["table"] == "rating":
            continue
        table = truth.rating.probs if c["table"] == "rating" and truth.rating is not None else getattr(truth, c["table"])
        out.append(abs(c["estimate"] - float(table[tuple(c["index"])])))
    return np.array(out)


def report(label: str, result: FitResult, truth: TrustModel, seconds: float) -> None:
    e = errors(result, truth)
    a = errors(result, truth, actions_only=True)
    print(
        f"  {label:34s} cells {len(e):3d}  MAE {e.mean():.4f}  max {e.max():.4f}  (action-model cells: {len(a)}, MAE {a.mean():.4f})  "
        f"log-lik {result.loglik:12.3f}  {seconds:6.1f} s  ({result.runs[result.best].ended})",
        flush=True,
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--participants", type=int, default=None)
    ap.add_argument("--restarts", type=int, default=10)
    args = ap.parse_args()
    n = args.participants or (300 if args.quick else 1000)
    truth = paper_model().replace(rating=RATING)
    print(f"uptime: {os.getloadavg()[0]:.2f} (1-minute load average)")
    fit_trust_model(
        simulate_design(truth, 20, seed=9, n_trials=(10, 10), rating_every=1), options=FitOptions(restarts=1), rating="rating"
    )  # compile
    for every in (1, 5):
        frame = simulate_design(truth, n, seed=1, n_trials=(10, 10), rating_every=every)
        rated = int(frame["rating"].notna().sum())
        when = "every trial" if every == 1 else f"every {every}th trial"
        print(f"{n} participants x 20 trials, a rating on {when} ({rated} ratings), {args.restarts} starts:")
        t = time.perf_counter()
        joint = fit_trust_model(frame, options=FitOptions(restarts=args.restarts, seed=0, n_jobs=1), rating="rating")
        report("joint (actions + ratings)", joint, truth, time.perf_counter() - t)
        if every == 1:
            t = time.perf_counter()
            alone = fit_trust_model(frame, options=FitOptions(restarts=args.restarts, seed=0, n_jobs=1))
            report("baseline: actions alone", alone, truth, time.perf_counter() - t)
            t = time.perf_counter()
            ratings = fit_trust_model(
                frame, options=FitOptions(restarts=args.restarts, seed=0, n_jobs=1), rating="rating", actions=False
            )
            report("ratings alone", ratings, truth, time.perf_counter() - t)


if __name__ == "__main__":
    main()
