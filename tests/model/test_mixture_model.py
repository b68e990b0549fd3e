"""Supervisor types: the mixture file format, presets and populations drawn from it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from trustseek.model import (
    ModelError,
    TypeMixture,
    conservative_model,
    load_mixture,
    paper_conservative_mixture,
    paper_model,
)
from trustseek.model.mixture import MIXTURE_FORMAT
from trustseek.simulation import Supervisors
from trustseek.simulation.designs import simulate_design


def test_json_round_trip(tmp_path):
    mix = paper_conservative_mixture(0.25)
    path = tmp_path / "mix.json"
    mix.save(path)
    back = TypeMixture.load(path)
    assert back == mix
    assert back.names == ("paper", "conservative")
    assert back.weights.tolist() == [0.75, 0.25]
    assert json.loads(path.read_text())["format"] == MIXTURE_FORMAT


def test_a_plain_model_file_is_one_type(tmp_path):
    path = tmp_path / "model.json"
    paper_model().save(path)
    mix = load_mixture(path)
    assert mix.n_types == 1 and mix.weights.tolist() == [1.0]
    assert mix.models[0] == paper_model()


def test_presets():
    assert load_mixture("paper+conservative") == paper_conservative_mixture()
    assert load_mixture("conservative").models[0] == conservative_model()
    with pytest.raises(ModelError, match="unknown mixture preset"):
        load_mixture("nobody")


def test_every_problem_is_reported(tmp_path):
    d = paper_conservative_mixture().to_dict()
    d["types"][0]["weight"] = -1
    d["types"][1]["name"] = ""
    d["types"][1]["model"]["initial"] = {"low": 0.5, "high": 0.6}
    d["extra"] = 1
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(d))
    with pytest.raises(ModelError) as exc:
        TypeMixture.load(path)
    text = str(exc.value)
    assert "bad.json" in text
    for needle in ("types[0].weight", "types[1].name", "types[1].model", "unknown keys ['extra']"):
        assert needle in text


def test_types_must_share_levels():
    three = paper_model().replace(
        trust_levels=("low", "mid", "high"),
        initial=np.array([0, 0, 1.0]),
        emission=np.repeat(paper_model().emission[:, :, :1], 3, axis=2),
        transition=np.broadcast_to(np.eye(3), (2, 2, 2, 3, 3)),
    )
    with pytest.raises(ModelError, match="every type must share them"):
        TypeMixture(("a", "b"), np.array([0.5, 0.5]), (paper_model(), three))
    with pytest.raises(ModelError, match="sum to 1"):
        TypeMixture(("a", "b"), np.array([0.5, 0.6]), (paper_model(), conservative_model()))


def test_population_shares_and_draws():
    mix = paper_conservative_mixture(0.3)
    sup = Supervisors.from_mixture(mix, 101, rng=3)
    assert np.bincount(sup.index).tolist() == [71, 30]
    assert sup.model_of(int(np.flatnonzero(sup.index == 1)[0])) == conservative_model()
    drawn = Supervisors.from_mixture(mix, 2000, rng=3, draw=True)
    assert abs(drawn.index.mean() - 0.3) < 0.04


def test_conservative_supervisors_intervene_more_in_low_complexity():
    sup = Supervisors.from_mixture(paper_conservative_mixture(0.5), 40, rng=0)
    log = simulate_design(sup, 40, seed=0)
    low = log[(log.complexity == "low") & (log.robot_action == "autonomous")]
    rate = low.assign(i=low.human_action.eq("intervene")).groupby("participant").i.mean()
    # participant i of the log is row i of the population
    type_of = dict(zip(log.participant.unique(), sup.index, strict=True))
    types = np.array([type_of[p] for p in rate.index])
    assert rate[types == 1].mean() > 3 * rate[types == 0].mean()
