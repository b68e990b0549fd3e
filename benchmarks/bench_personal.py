"""Benchmark and acceptance figures of the per-person models (``personalize``), both estimates of s.

    python benchmarks/bench_personal.py            # 100 participants x 71 trials, 3 draws per population
    python benchmarks/bench_personal.py --reps 1   # one draw
    python benchmarks/bench_personal.py c5 types   # some populations

Populations (``simulate_design``, the paper's design, 71 trials each), all with the pooled fit
of the log (3 restarts) as the centre:

* ``none``: every participant is the paper's model (no individual differences);
* ``c50`` / ``c5``: ``Supervisors.dirichlet`` around the paper's model, concentration 50 and 5
  (every row of each person drawn from Dirichlet(c * the paper's row): c is the true s);
* ``types``: ``paper_conservative_mixture(0.5)`` (two supervisor types, half each);
* ``c50x4``: ``c50`` with four times the trials (284 each): small differences need more trials.

Each line: the estimate (held-out or variational), s per table (``*``: at the bound), the
criterion's gain over the centre, the CPU seconds of ``personalize`` (the pooled fit's are the
in-run baseline), then two checks against the truth: the mean absolute error of
P(rely | trust, complexity, autonomous) over the participants (personal models; the centre's in
the header), and the log-likelihood of a new log of the same people (another 71 trials each)
under their personal models minus under the centre (the true models' gain in the header).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from trustseek.estimation import encode, fit_trust_model
from trustseek.estimation.options import FitOptions
from trustseek.estimation.personal import _PersonalWorkspace, personalize
from trustseek.estimation.spec import TABLES, Params
from trustseek.estimation.structure import Structure
from trustseek.estimation.trust_iohmm import from_model
from trustseek.model.core import TrustModel
from trustseek.model.presets import paper_conservative_mixture, paper_model
from trustseek.simulation.designs import simulate_design
from trustseek.simulation.populations import Supervisors
from trustseek.vocab import PAPER_DATA_COUNTS


def population(name: str, n: int, seed: int) -> Supervisors:
    pm = paper_model()
    name = name.removesuffix("x4")
    if name == "none":
        return Supervisors.dirichlet(pm, n, 1e12, rng=seed)
    if name == "types":
        return Supervisors.from_mixture(paper_conservative_mixture(0.5), n, rng=seed)
    return Supervisors.dirichlet(pm, n, float(name[1:]), rng=seed)


def rely_error(models: list[TrustModel], truth: list[TrustModel]) -> float:
    """Mean over participants of the mean |P(rely | T, C, autonomous) - the truth's| over the 4 rows."""
    return float(
        np.mean([np.abs(m.emission[:, 0, :, 1] - t.emission[:, 0, :, 1]).mean() for m, t in zip(models, truth, strict=True)])
    )


def new_loglik(df, models: list[TrustModel]) -> float:
    """Log-likelihood of log ``df`` with participant n under ``models[n]``."""
    spec, _ = from_model(models[0])
    seqs = encode(df, spec)
    work = _PersonalWorkspace(seqs, *Structure(spec, seqs).dims, method="compiled")
    params = Params.stack([from_model(m)[1] for m in models])
    return float(work.estep(params).loglik.sum())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--participants", type=int, default=100)
    ap.add_argument("--reps", type=int, default=3, help="draws of each population")
    ap.add_argument("populations", nargs="*", default=["none", "c50", "c5", "types", "c50x4"])
    args = ap.parse_args()
    n = args.participants
    personalize(simulate_design(paper_model(), 3, seed=0), paper_model(), strength=1.0)  # load the compiled passes
    print(f"{n} participants, the pooled fit as the centre, one thread; load {os.getloadavg()[0]:.1f}")
    for name in args.populations:
        trials = [4 * c for c in PAPER_DATA_COUNTS] if name.endswith("x4") else PAPER_DATA_COUNTS
        for rep in range(args.reps):
            sup = population(name, n, 100 * rep + 1)
            df = simulate_design(sup, n, seed=100 * rep + 2, n_trials=trials)
            new = simulate_design(sup, n, seed=100 * rep + 3, n_trials=trials)
            truth = [sup.model_of(i) for i in range(n)]
            t = time.process_time()
            pooled = fit_trust_model(df, options=FitOptions(restarts=3)).model
            fit_cpu = time.process_time() - t
            centre_new = new_loglik(new, [pooled] * n)
            print(
                f"{name:>5} draw {rep + 1}: pooled fit {fit_cpu:.2f} s CPU; centre's error {rely_error([pooled] * n, truth):.4f}; "
                f"true models' gain on new trials {new_loglik(new, truth) - centre_new:+.1f}"
            )
            for estimate in ("held-out", "variational"):
                t = time.process_time()
                res = personalize(df, pooled, estimate=estimate)
                cpu = time.process_time() - t
                s = " ".join(f"{k[:4]} {res.strength[k]:8.3g}{'*' if res.at_bound[k] else ' '}" for k in TABLES)
                print(
                    f"        {estimate:<11} s: {s}  criterion {res.score - res.score_centre:+7.2f}  {cpu:5.2f} s CPU  "
                    f"error {rely_error(res.models, truth):.4f}  new trials {new_loglik(new, res.models) - centre_new:+7.2f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
