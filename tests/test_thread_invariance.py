"""Results do not depend on how many threads the machine's BLAS runs: a threaded BLAS splits
products and sums differently with the cores, and the solvers and the design study pick vectors
and thresholds at near ties, so their numbers changed in the last digits (the reproduction's
fitted-types policy moved by 1.4e-4). Every solver and the design study run BLAS on one thread."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from trustseek.solvers import make_solver
from trustseek.solvers.base import one_blas_thread
from trustseek.solvers.registry import SOLVERS


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_one_blas_thread_limits_blas_inside_and_restores_it_after():
    with threadpool_limits(limits=2, user_api="blas"):
        outside = _blas_threads()
        inside = one_blas_thread()(_blas_threads)()
        assert all(n == 1 for n in inside) and _blas_threads() == outside


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_every_solver_solves_with_one_blas_thread(name):
    solver = make_solver(name)
    for method in ("solve", "solve_bounds"):
        if hasattr(solver, method):
            assert hasattr(getattr(type(solver), method), "__wrapped__"), f"{name}.{method} is not wrapped"


def test_the_design_study_gives_the_same_numbers_on_one_and_two_threads():
    """The default sweep's JSON differed in the 13th digit of its thresholds (a dense linear solve)."""
    outs = []
    for threads in ("1", "2"):
        env = {**os.environ, "OMP_NUM_THREADS": threads, "OPENBLAS_NUM_THREADS": threads}
        run = subprocess.run(
            [sys.executable, "-m", "trustseek", "design", "--replicates", "6", "--json"],
            capture_output=True,
            text=True,
            env=env,
            timeout=600,
            check=False,
        )
        assert run.returncode == 0, run.stderr
        outs.append(json.loads(run.stdout))
    assert outs[0] == outs[1]
