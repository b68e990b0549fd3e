"""``write_csv`` writes what ``DataFrame.to_csv(index=False)`` writes, byte for byte, whichever of
its two writers it takes."""

import math

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from trustseek.data.trials import write_csv

# text that needs no quotes (empty, padded, non-ASCII, missing, like a number) and text that does
PLAIN = ["", "low", " high ", "ü-ñ", "1.0", "nan", "NA", "True"]
QUOTED = ["a,b", 'say "hi"', "x\ny", "r\r"]
floats = st.one_of(
    st.sampled_from([0.0, -0.0, 1.0, 2.0, 0.1, 1e-300, 1e22, 123456789.125, math.inf, -math.inf, math.nan]),
    st.floats(allow_nan=True, allow_infinity=True),
)


@st.composite
def frames(draw) -> pd.DataFrame:
    rows = draw(st.integers(0, 12))
    plain = draw(st.booleans())  # mostly Arrow's writer; else a column or a name that pandas writes
    texts = st.one_of(st.none(), st.sampled_from(PLAIN if plain else PLAIN + QUOTED))
    kinds = ["text", "str", "category", "int", "int8", "float", "bool"] + ([] if plain else ["float32", "nullable"])
    columns = {}
    for j in range(draw(st.integers(1, 5))):
        kind = draw(st.sampled_from(kinds))
        if kind in ("text", "str", "category"):
            values = draw(st.lists(texts, min_size=rows, max_size=rows))
            col = pd.Series(values, dtype={"text": object, "str": "str", "category": "category"}[kind])
        elif kind in ("int", "int8"):
            col = pd.Series(draw(hnp.arrays(np.int64 if kind == "int" else np.int8, rows)))
        elif kind == "nullable":
            col = pd.Series(draw(st.lists(st.one_of(st.none(), st.integers(-5, 5)), min_size=rows, max_size=rows)), dtype="Int64")
        elif kind == "bool":
            col = pd.Series(draw(hnp.arrays(np.bool_, rows)))
        else:
            values = draw(st.lists(floats if kind == "float" else st.floats(width=32), min_size=rows, max_size=rows))
            col = pd.Series(np.array(values, dtype=np.float64 if kind == "float" else np.float32))
        columns[draw(st.sampled_from([f"c{j}", f"name {j}", f"ü{j}"] + ([] if plain else [f"a,{j}"])))] = col
    return pd.DataFrame(columns)


@settings(max_examples=300, deadline=None)
@given(frame=frames())
def test_the_same_bytes_as_pandas(tmp_path_factory, frame):
    folder = tmp_path_factory.mktemp("csv")
    frame.to_csv(folder / "pandas.csv", index=False)
    write_csv(frame, folder / "ours.csv")
    assert (folder / "ours.csv").read_bytes() == (folder / "pandas.csv").read_bytes()


def test_a_simulated_log_takes_the_fast_writer(tmp_path, monkeypatch):
    """Text, whole numbers and floats with no field to quote go through Arrow, not pandas."""
    from trustseek import paper_model, paper_task
    from trustseek.policies import TrustAwarePolicy
    from trustseek.simulation import simulate

    task = paper_task()
    grid = np.linspace(0.0, 1.0, 11)
    q = np.zeros((11, 2, 2))
    q[:, 1, 1] = 0.5 - grid
    sim = simulate(
        paper_model(), task, TrustAwarePolicy(grid, q, paper_model(), task.complexities, "bayes"), 40, counts=(4, 3), seed=1
    )
    frame = sim.trials()
    assert frame["belief"].notna().all()
    frame.to_csv(tmp_path / "pandas.csv", index=False)
    monkeypatch.setattr(pd.DataFrame, "to_csv", lambda *a, **k: (_ for _ in ()).throw(AssertionError("pandas wrote it")))
    write_csv(frame, tmp_path / "ours.csv")
    assert (tmp_path / "ours.csv").read_bytes() == (tmp_path / "pandas.csv").read_bytes()
