"""Acceptance: a canonical log written in every layout a study may keep it in, read by a mapping
alone, fits to the canonical log's log-likelihood (the joint fit of actions and block ratings).

Layouts: a wide CSV (a row per participant, a column per trial of each field); a long CSV with the study's names, labels and a trial number restarting in every block;
the same as a JSON array, JSON lines and Parquet; a record per participant with per-trial lists;
a record per block with per-trial lists; the ratings in a second file, one row per block.  In
every layout the block's rating is copied onto each of its trials (``"per": "block"``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trustseek.data import read_trials
from trustseek.estimation import fit_trust_model
from trustseek.estimation.options import FitOptions

LEVELS = ("1", "2", "3", "4")
NAMES = {"participant": "pid", "complexity": "hard", "robot_action": "asked", "human_action": "took_over", "experience": "ok"}
LABELS = {
    "complexity": {"0": "low", "1": "high"},
    "robot_action": {"0": "autonomous", "1": "ask"},
    "human_action": {"1": "intervene", "0": "rely"},
    "experience": {"1": "reliable", "0": "faulty"},
}


def canonical_log(seed: int, people: int, blocks: int, size: int) -> pd.DataFrame:
    """Random trials that obey the experience rule; a rating on the last trial of each block."""
    rng = np.random.default_rng(seed)
    n = people * blocks * size
    cx = rng.choice(["low", "high"], n)
    ask = rng.random(n) < 0.3
    rely = ~ask & (rng.random(n) < 0.7)
    success = rng.random(n) < 0.8
    experience = np.where(ask, np.where(cx == "high", "reliable", "faulty"), np.where(rely & success, "reliable", "faulty"))
    t = np.tile(np.arange(blocks * size), people)
    last = t % size == size - 1
    return pd.DataFrame(
        {
            "participant": np.repeat([f"S{i}" for i in range(people)], blocks * size),
            "trial": t + 1,
            "complexity": cx,
            "robot_action": np.where(ask, "ask", "autonomous"),
            "human_action": np.where(rely, "rely", "intervene"),
            "experience": experience,
            "block": t // size + 1,
            "rating": np.where(last, rng.choice(LEVELS, n), None),
        }
    )


def study_log(canonical: pd.DataFrame, size: int, seed: int) -> pd.DataFrame:
    """The log as the study keeps it: its names and 0/1 codes, the trial number restarting in
    every block, the block's rating on each of its trials, rows shuffled within a participant."""
    log = pd.DataFrame({"pid": canonical.participant, "block": canonical.block, "in_block": (canonical.trial - 1) % size + 1})
    for canon, table in LABELS.items():
        back = {v: int(k) for k, v in table.items()}
        log[NAMES[canon]] = canonical[canon].map(back)
    log["trust"] = canonical.groupby(["participant", "block"]).rating.transform("last").astype(int)
    rng = np.random.default_rng(seed)
    log = log.assign(_r=rng.random(len(log))).sort_values(["pid", "_r"], kind="stable").drop(columns="_r")
    return log.reset_index(drop=True)


MAPPING = {
    "columns": NAMES,
    "labels": LABELS,
    "order": ["block", "in_block"],
    "rating": {"column": "trust", "levels": [int(x) for x in LEVELS], "per": "block"},
}


def write_layouts(log: pd.DataFrame, folder: Path) -> dict[str, tuple[Path, dict]]:
    trials = [c for c in log.columns if c not in ("pid",)]
    per_person = [{"pid": p, **{c: g[c].tolist() for c in trials}} for p, g in log.groupby("pid", sort=False)]
    in_block = [c for c in trials if c not in ("block", "trust")]
    per_block = [
        {"pid": p, "block": int(b), "trust": int(g.trust.iloc[0]), **{c: g[c].tolist() for c in in_block}}
        for (p, b), g in log.groupby(["pid", "block"], sort=False)
    ]
    ratings = log[["pid", "block", "trust"]].drop_duplicates()
    wide = log.assign(t=log.groupby("pid").cumcount() + 1).pivot(index="pid", columns="t", values=trials)
    wide.columns = [f"{field}_{t}" for field, t in wide.columns]
    out = {
        "wide CSV": (folder / "wide.csv", {**MAPPING, "wide": trials}),
        "long CSV": (folder / "log.csv", MAPPING),
        "JSON array": (folder / "log.json", MAPPING),
        "JSON lines": (folder / "log.jsonl", MAPPING),
        "Parquet": (folder / "log.parquet", MAPPING),
        "record per participant": (folder / "people.json", {**MAPPING, "explode": trials}),
        "record per block": (folder / "blocks.jsonl", {**MAPPING, "explode": in_block}),
        "joined ratings": (folder / "actions.csv", {**MAPPING, "join": {"file": str(folder / "ratings.csv")}}),
    }
    wide.reset_index().to_csv(out["wide CSV"][0], index=False)
    log.to_csv(out["long CSV"][0], index=False)
    log.to_json(out["JSON array"][0], orient="records")
    log.to_json(out["JSON lines"][0], orient="records", lines=True)
    log.to_parquet(out["Parquet"][0])
    out["record per participant"][0].write_text(json.dumps(per_person))
    out["record per block"][0].write_text("".join(json.dumps(r) + "\n" for r in per_block))
    log.drop(columns="trust").to_csv(out["joined ratings"][0], index=False)
    ratings.to_csv(folder / "ratings.csv", index=False)
    return out


def fitted(frame: pd.DataFrame) -> float:
    return fit_trust_model(
        frame, options=FitOptions(restarts=1, seed=1, max_iter=25, n_jobs=1), rating="rating", rating_levels=LEVELS
    ).loglik


@settings(max_examples=3, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    seed=st.integers(0, 10_000),
    people=st.integers(2, 4),
    blocks=st.integers(1, 3),
    size=st.integers(2, 4),
)
def test_every_layout_fits_by_its_mapping_to_the_canonical_loglik(tmp_path_factory, seed, people, blocks, size):
    canonical = canonical_log(seed, people, blocks, size)
    reference = fitted(read_trials(canonical, {"rating": {"column": "rating", "levels": list(LEVELS)}}))
    folder = tmp_path_factory.mktemp("layouts")
    for layout, (path, mapping) in write_layouts(study_log(canonical, size, seed), folder).items():
        frame = read_trials(path, mapping)
        assert frame.rating.notna().sum() == people * blocks, layout
        assert fitted(frame) == pytest.approx(reference, rel=1e-9, abs=1e-9), layout
