"""A fit starts fast: every fit runs the compiled code built with the package (no numba, and no
scipy.optimize for the compiled run); ``never_estimated`` (whole arrays, no
longer a walk over every row in Python) says what a row-by-row reading of the log says, on logs
in any row order, with gaps in the trial numbers, missing human actions and experiences."""

from __future__ import annotations

import subprocess
import sys

import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek.estimation import encode
from trustseek.estimation.estep import Workspace
from trustseek.estimation.fit import never_estimated
from trustseek.estimation.structure import Structure
from trustseek.estimation.trust_iohmm import paper_spec
from trustseek.vocab import ACTIONS, EXPERIENCES

COMPLEXITIES = ("low", "high")


def row_by_row(frame: pd.DataFrame, fixed_ask: bool) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """The rows no trial informs, read one trial at a time."""
    em_seen, tr_seen = set(), set()
    rows = frame.to_dict("records")
    for r in rows:
        key = (COMPLEXITIES.index(r["complexity"]), ACTIONS.index(r["robot_action"]))
        if pd.notna(r["human_action"]):
            em_seen.add(key)
        later = [s for s in rows if s["participant"] == r["participant"] and s["trial"] > r["trial"]]
        if later and pd.notna(r["experience"]):
            tr_seen.add((*key, EXPERIENCES.index(r["experience"])))
    out: list[tuple[str, tuple[int, ...]]] = []
    for i in range(2):
        for j in range(2):
            if (i, j) not in em_seen and not (fixed_ask and j == 1):
                out.append(("emission", (i, j)))
            out += [("transition", (i, j, k)) for k in range(2) if (i, j, k) not in tr_seen]
    return tuple(out)


trial_rows = st.lists(
    st.tuples(
        st.sampled_from(["P1", "P2", "P3"]),
        st.sampled_from(COMPLEXITIES),
        st.sampled_from(ACTIONS),
        st.sampled_from(["intervene", "rely", None]),
        st.sampled_from([*EXPERIENCES, None]),
    ),
    min_size=0,
    max_size=12,
)


@settings(max_examples=50, deadline=None)
@given(rows=trial_rows, shuffle=st.randoms(use_true_random=False))
def test_never_estimated_is_the_row_by_row_answer(rows, shuffle):
    trials: dict[str, int] = {}
    records = []
    for p, c, a, h, e in rows:
        trials[p] = trials.get(p, 0) + shuffle.choice([1, 2])  # gaps in the numbering
        records.append(
            {"participant": p, "trial": trials[p], "complexity": c, "robot_action": a, "human_action": h, "experience": e}
        )
    shuffle.shuffle(records)
    frame = pd.DataFrame(records, columns=["participant", "trial", "complexity", "robot_action", "human_action", "experience"])
    frame = frame.astype({"participant": "category", "trial": "int64"})
    spec = paper_spec()
    fixed_ask = any(dict(f.where) == {"robot_action": "ask"} for f in spec.fixed_emissions)
    assert never_estimated(frame, spec) == row_by_row(frame, fixed_ask)


def run_python(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=True)
    return out.stdout.strip().splitlines()[-1]


def test_a_fit_of_any_size_runs_compiled():
    """The compiled code is built with the package: a fit of a dozen trials runs it too (the numpy
    E-step is the reference, on request)."""
    rows = [
        {"participant": f"P{p}", "trial": t, "complexity": "low", "robot_action": "autonomous", "human_action": "rely"}
        for p in range(3)
        for t in range(1, 5)
    ]
    frame = pd.DataFrame(rows).assign(experience="reliable")
    spec = paper_spec()
    seqs = encode(frame, spec)
    assert Workspace(seqs, *Structure(spec, seqs).dims).compiled
    reference = Workspace(seqs, *Structure(spec, seqs).dims, method="loop")
    assert not reference.compiled and reference._kernel is None


def test_the_shipped_example_fits_compiled_without_numba_or_scipy_optimize():
    """A fit compiles nothing and imports no numba; scipy.optimize (half a second of CPU) is
    imported by the numpy path's finish when it runs (a rating, the types), never by the compiled
    run, and scipy.linalg (0.13-0.16 s) neither: its BLAS routines are found in scipy's library
    (:mod:`~trustseek.estimation.blas`).  The example's log-likelihood is the README's."""
    code = (
        "import sys\n"
        "from trustseek.data import example_path, read_trials\n"
        "from trustseek.estimation import FitOptions, fit_trust_model, forward_backward\n"
        "r = fit_trust_model(read_trials(example_path()), options=FitOptions(restarts=2, n_jobs=1))\n"
        "print(f'{r.loglik:.4f}', forward_backward.__file__.endswith('.so'), 'numba' in sys.modules, "
        "'scipy.optimize' in sys.modules, 'scipy.linalg' in sys.modules)"
    )
    assert run_python(code).split() == ["-69.9113", "True", "False", "False", "False"]
