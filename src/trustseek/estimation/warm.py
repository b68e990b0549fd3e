"""Compile the fit's numba kernels into numba's on-disk cache, once (about a minute of CPU; later
processes load them in a fraction of a second): ``python -m trustseek.estimation.warm`` runs both fit
paths, a rating and two supervisor types on a tiny made-up log.  ``make test`` runs it.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from ..compiled import load as load_compiled
from .fit import fit_trust_model
from .forward_backward import step_codes
from .iohmm import fit_iohmm
from .kernels import many_fits
from .mixture import fit_types
from .options import FitOptions
from .sequences import encode
from .trust_iohmm import preset_spec


def tiny_log(participants: int = 4, trials: int = 12, seed: int = 0) -> pd.DataFrame:
    """A made-up trial log in the canonical columns (with a rating), only for compiling."""
    rng = np.random.default_rng(seed)
    rows = []
    for p in range(participants):
        for t in range(1, trials + 1):
            ask = rng.random() < 0.3
            rows.append(
                {
                    "participant": f"P{p}",
                    "trial": t,
                    "complexity": ("low", "high")[int(rng.integers(2))],
                    "robot_action": "ask" if ask else "autonomous",
                    "human_action": "intervene" if ask or rng.random() < 0.3 else "rely",
                    "experience": ("faulty", "reliable")[int(rng.integers(2))],
                    "rating": str(int(rng.integers(1, 4))),
                }
            )
    return pd.DataFrame(rows)


def first_kernel() -> None:
    """The first compiled call of a fit, on made-up arrays: it sets up numba's code generator and
    cache (what :func:`~trustseek.compiled.load_meanwhile` runs while a large log is read)."""
    codes = np.zeros((1, 2), dtype=np.int32)
    step_codes(codes, codes.copy(), 2)


def warm() -> float:
    """Run every compiled path once on :func:`tiny_log`; the seconds it took."""
    t = time.perf_counter()
    load_compiled()
    frame = tiny_log()
    spec = preset_spec("paper", frame)
    seqs = encode(frame, spec)
    # inside many_fits the E-steps run compiled on this log of fewer than kernels.COMPILE_MIN trials
    with many_fits():
        for compiled in (True, False):
            fit_iohmm(seqs, spec, options=FitOptions(restarts=1, max_iter=5, n_jobs=1), compiled=compiled)
        fit_trust_model(
            frame, options=FitOptions(restarts=1, max_iter=5, n_jobs=1), rating="rating", rating_levels=("1", "2", "3")
        )
        fit_types(frame, 2, options=FitOptions(restarts=1, max_iter=5, n_jobs=1))
    return time.perf_counter() - t


if __name__ == "__main__":
    import sys

    sys.stdout.write(f"compiled the fit's kernels in {warm():.1f} s\n")
