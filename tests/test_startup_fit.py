"""The fit's whole-array bookkeeping: ``never_estimated`` (vectorized, it no longer walks every
row in Python) says what a row-by-row reading of the log says, on logs in any row order, with
gaps in the trial numbers, missing human actions and experiences."""

from __future__ import annotations

import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek.estimation.fit import never_estimated
from trustseek.estimation.trust_iohmm import paper_spec
from trustseek.vocab import ACTIONS, EXPERIENCES

COMPLEXITIES = ("low", "high")


def row_by_row(frame: pd.DataFrame, fixed_ask: bool) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """The rows no trial informs, read one trial at a time."""
    em_seen, tr_seen = set(), set()
    for _, r in frame.iterrows():
        key = (COMPLEXITIES.index(r["complexity"]), ACTIONS.index(r["robot_action"]))
        if pd.notna(r["human_action"]):
            em_seen.add(key)
        later = frame[(frame["participant"] == r["participant"]) & (frame["trial"] > r["trial"])]
        if len(later) and pd.notna(r["experience"]):
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


@settings(max_examples=150, deadline=None)
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
