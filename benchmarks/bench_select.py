"""Benchmark of ``trustseek select`` (the number of trust levels) and its acceptance figures.

    python benchmarks/bench_select.py               # timing: three-level model, 60 x 40, K = 1..3, 2 folds
    python benchmarks/bench_select.py --acceptance  # three- and four-level models, 300 x 60, K = 1..K+1, defaults

Acceptance (per generating model; seeded): the number of levels chosen by BIC and by the
5-fold participant-held-out log-likelihood with select's defaults; the best
log-likelihood of the generating number of levels that select found against the best
of ``--reference`` random restarts (the in-run baseline); select's time.  And what the
data can resolve at all: the log-likelihood, BIC and held-out score of the generating
model at its TRUE parameters against the fitted model with one level fewer (the true
model's held-out score needs no training: it is its log-likelihood on every participant).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from trustseek import TrustModel, trust_model
from trustseek.data.trials import example_path
from trustseek.estimation import select_levels
from trustseek.estimation.iohmm import fit_iohmm, loglik
from trustseek.estimation.options import FitOptions
from trustseek.estimation.selection import BEST_TOLERANCE
from trustseek.estimation.sequences import encode
from trustseek.estimation.trust_iohmm import from_model, level_names, preset_spec
from trustseek.simulation.designs import simulate_design


def four_level_model() -> TrustModel:
    """P(rely | high complexity, autonomous) 0.15, 0.45, 0.75, 0.97 (low complexity 0.9 .. 0.995);
    a reliable experience moves trust one level up with probability 0.35 in high complexity,
    0.1 in low; a faulty one one level down with 0.6 (0.2 after asking)."""
    K = 4
    em = np.zeros((2, 2, K, 2))  # (complexity, action, trust, intervene/rely)
    em[0, 0, :, 1] = [0.9, 0.95, 0.98, 0.995]
    em[1, 0, :, 1] = [0.15, 0.45, 0.75, 0.97]
    em[:, 0, :, 0] = 1 - em[:, 0, :, 1]
    em[:, 1, :, 0] = 1.0
    tr = np.zeros((2, 2, 2, K, K))  # (complexity, action, experience faulty/reliable, from, to)
    for c in range(2):
        for a in range(2):
            for e in range(2):
                for t in range(K):
                    if e == 1:
                        p, to = (0.35 if c == 1 else 0.1), min(t + 1, K - 1)
                    else:
                        p, to = (0.6 if a == 0 else 0.2), max(t - 1, 0)
                    tr[c, a, e, t, to] += p
                    tr[c, a, e, t, t] += 1 - p
    return trust_model(("low", "medium-low", "medium-high", "high"), ("low", "high"), np.array([0.1, 0.2, 0.3, 0.4]), em, tr)


def three_level_model() -> TrustModel:
    return TrustModel.load(example_path("three_level_model.json"))


def chain(rely_high: list[float], rely_low: list[float], up: tuple[float, float], down: tuple[float, float]) -> TrustModel:
    """Levels in a chain: P(rely | autonomous) per level in high and low complexity; a reliable
    experience moves trust one level up with probability ``up[complexity]`` (low, high), a faulty
    one one level down with ``down[robot action]`` (autonomous, ask); every level equally likely
    at the start."""
    K = len(rely_high)
    em = np.zeros((2, 2, K, 2))
    em[0, 0, :, 1], em[1, 0, :, 1] = rely_low, rely_high
    em[:, 0, :, 0] = 1 - em[:, 0, :, 1]
    em[:, 1, :, 0] = 1.0
    tr = np.zeros((2, 2, 2, K, K))
    for c, a, e, t in np.ndindex(2, 2, 2, K):
        p, to = (up[c], min(t + 1, K - 1)) if e == 1 else (down[a], max(t - 1, 0))
        tr[c, a, e, t, to] += p
        tr[c, a, e, t, t] += 1 - p
    return trust_model(level_names(K), ("low", "high"), np.full(K, 1.0 / K), em, tr)


def separated_three() -> TrustModel:
    """Three levels that 300 x 60 trials resolve: P(rely | high complexity) 0.02, 0.5, 0.98."""
    return chain([0.02, 0.5, 0.98], [0.1, 0.6, 0.99], up=(0.05, 0.12), down=(0.2, 0.08))


def separated_four() -> TrustModel:
    """Four levels, P(rely | high complexity) 0.02, 0.3, 0.7, 0.98, moving slowly."""
    return chain([0.02, 0.3, 0.7, 0.98], [0.05, 0.4, 0.8, 0.99], up=(0.03, 0.06), down=(0.06, 0.03))


MODELS = {
    "three": three_level_model,
    "four": four_level_model,
    "three-separated": separated_three,
    "four-separated": separated_four,
}


def table(model: TrustModel, n: int, trials: int, levels: tuple[int, ...], folds: int, reference: int, seed: int) -> None:
    K = model.n_trust
    df = simulate_design(model, n, seed=seed, n_trials=(trials // 2, trials - trials // 2))
    t = time.perf_counter()
    rows = select_levels(df, levels=levels, folds=folds, options=FitOptions(restarts=None, seed=0, tol=1e-6, n_jobs=1))
    wall = time.perf_counter() - t
    print(
        f"{K}-level model, {n} participants x {trials} trials (seed {seed}); select K = {levels[0]}..{levels[-1]}, {folds} folds"
    )
    print("  K   loglik     starts reached  params  BIC       held-out")
    for r in rows:
        mark = ("  <- BIC" if r["best_bic"] else "") + ("  <- held-out" if r["best_heldout"] else "")
        print(
            f"  {r['levels']}  {r['loglik']:10.3f}  {r['starts']:5d}  {r['reached_best']:5d}  {r['n_params']:6d}"
            f"  {r['bic']:8.1f}  {r['heldout_loglik']:10.3f}{mark}"
        )
    by = {r["levels"]: r for r in rows}
    bic = min(rows, key=lambda r: r["bic"])["levels"]
    held = max(rows, key=lambda r: r["heldout_loglik"])["levels"]
    print(f"  chosen: BIC {bic}, held-out {held} (generating: {K}); select took {wall:.0f} s")
    spec, params = from_model(model)
    true_ll = loglik(encode(df, spec), spec, params)
    if K in by and K - 1 in by:
        fit, lower = by[K], by[K - 1]
        penalty = fit["bic"] + 2 * fit["loglik"]  # n_params * log(observations)
        true_bic = penalty - 2 * true_ll
        print(
            f"  TRUE parameters: log-likelihood {true_ll:.3f} ({true_ll - lower['loglik']:+.3f} against the fitted "
            f"{K - 1} levels); BIC {true_bic:.1f} ({true_bic - lower['bic']:+.1f} against the fitted {K - 1} levels); "
            f"held-out {true_ll:.3f} ({true_ll - lower['heldout_loglik']:+.3f} against the fitted {K - 1} levels' held-out)"
        )
    if reference and K in by:
        base = preset_spec("paper", df)
        t = time.perf_counter()
        ref = fit_iohmm(
            encode(df, base), base.with_levels(level_names(K)), options=FitOptions(restarts=reference, seed=0, tol=1e-6, n_jobs=1)
        )
        ll = np.asarray(ref.restart_logliks)
        hits = int((ll >= ll.max() - BEST_TOLERANCE).sum())
        print(
            f"  {K} levels: select's fit {by[K]['loglik']:.3f}; {reference} random restarts: {ll.max():.3f} "
            f"(reached by {hits}; {time.perf_counter() - t:.0f} s): select {by[K]['loglik'] - ll.max():+.3f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--acceptance", action="store_true", help="the 300 x 60 table for the three- and four-level models")
    ap.add_argument("--reference", type=int, default=200, help="random restarts of the reference fit (0: none)")
    ap.add_argument(
        "--models",
        default="three-separated,four-separated,three,four",
        help=f"generating models (acceptance), comma-separated among {', '.join(MODELS)}",
    )
    args = ap.parse_args()
    print(f"load average: {os.getloadavg()[0]:.1f}")
    if not args.acceptance:
        table(three_level_model(), 60, 40, (1, 2, 3), folds=2, reference=min(args.reference, 20), seed=2)
        return
    for name in args.models.split(","):
        if name not in MODELS:
            ap.error(f"unknown model {name!r}; models: {', '.join(MODELS)}")
        model = MODELS[name]()
        print(f"model {name}:")
        table(model, 300, 60, tuple(range(1, model.n_trust + 2)), folds=5, reference=args.reference, seed=0)


if __name__ == "__main__":
    main()
