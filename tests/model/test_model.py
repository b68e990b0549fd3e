"""Trust model and task files: round trips, the paper preset, and validation."""

import copy
import dataclasses
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trustseek import ModelError, Task, TrustModel, trust_model
from trustseek.estimation.options import FitOptions
from trustseek.model.presets import PAPER_UNOBSERVED_CELLS, load_model, load_task


def test_paper_preset_numbers(model, task):
    d = model.to_dict()
    assert d["initial"] == {"low": 0.0, "high": 1.0}
    em = d["emission"]
    assert em["low"]["autonomous"]["high"]["rely"] == 1.0
    assert em["low"]["autonomous"]["low"]["rely"] == 0.98
    assert em["high"]["autonomous"]["high"]["rely"] == 0.95
    assert em["high"]["autonomous"]["low"]["rely"] == 0.46
    for c in ("low", "high"):
        for t in ("low", "high"):
            assert em[c]["ask"][t]["intervene"] == 1.0
    tr = d["transition"]
    assert tr["low"]["autonomous"]["reliable"]["high"]["high"] == 1.0
    assert tr["low"]["autonomous"]["reliable"]["low"]["low"] == 1.0
    assert tr["low"]["autonomous"]["faulty"]["high"]["low"] == pytest.approx(0.39)
    assert tr["low"]["autonomous"]["faulty"]["low"]["low"] == pytest.approx(0.99)
    assert tr["low"]["ask"]["faulty"]["high"]["high"] == 1.0
    assert tr["low"]["ask"]["faulty"]["low"]["low"] == 1.0
    assert tr["high"]["autonomous"]["reliable"]["high"]["high"] == 1.0
    assert tr["high"]["autonomous"]["reliable"]["low"]["high"] == 1.0
    assert tr["high"]["autonomous"]["faulty"]["high"]["low"] == 1.0
    assert tr["high"]["autonomous"]["faulty"]["low"]["low"] == pytest.approx(0.7)
    assert tr["high"]["ask"]["reliable"]["high"]["high"] == pytest.approx(0.94)
    assert tr["high"]["ask"]["reliable"]["low"]["high"] == pytest.approx(0.44)
    # never-observed cells are the identity, and documented
    assert tr["low"]["ask"]["reliable"]["low"] == {"low": 1.0, "high": 0.0}
    assert tr["high"]["ask"]["faulty"]["high"] == {"low": 0.0, "high": 1.0}
    assert len(PAPER_UNOBSERVED_CELLS) == 2
    assert task.success.tolist() == [0.97, 0.83]
    assert task.complexity_probs.tolist() == [0.5, 0.5]
    assert task.discount == 0.987
    assert task.rewards.to_dict() == {"autonomous_success": 2.0, "ask": 1.0, "intervene": 0.0, "autonomous_failure": -3.0}


def test_round_trip(tmp_path, model, task):
    model.save(tmp_path / "m.json")
    task.save(tmp_path / "t.json")
    assert TrustModel.load(tmp_path / "m.json") == model
    assert Task.load(tmp_path / "t.json") == task
    assert load_model(tmp_path / "m.json") == model
    assert load_task("paper") == task


def test_precise_row_sum_message(model):
    d = model.to_dict()
    d["transition"]["high"]["ask"]["reliable"]["low"] = {"low": 0.53, "high": 0.44}
    with pytest.raises(ModelError) as exc:
        TrustModel.from_dict(d)
    assert exc.value.problems == ["transition[C=high, a=ask, E=reliable][T=low] sums to 0.97"]


def test_every_problem_reported(model):
    d = model.to_dict()
    del d["emission"]["high"]["ask"]
    d["initial"] = {"low": -0.1, "high": 1.1}
    d["transition"]["low"]["autonomous"]["faulty"]["high"]["medium"] = 0.0
    with pytest.raises(ModelError) as exc:
        TrustModel.from_dict(d, "m.json")
    lines = exc.value.lines()
    assert "m.json: emission[C=high, a=ask] is missing" in lines
    assert "m.json: initial[low] = -0.1 is outside [0, 1]" in lines
    assert "m.json: initial[high] = 1.1 is outside [0, 1]" in lines
    assert any("transition[C=low, a=autonomous, E=faulty][T=high] has unknown entry 'medium'" in x for x in lines)
    assert len(lines) == 4


def test_task_validation(task):
    d = task.to_dict()
    d["complexities"]["high"]["success"] = 1.3
    d["complexities"]["low"]["ask_experience"] = "great"
    d["discount"] = 1.0
    with pytest.raises(ModelError) as exc:
        Task.from_dict(d)
    p = exc.value.problems
    assert "complexities[high].success = 1.3 must be a probability in [0, 1]" in p
    assert any("ask_experience = 'great'" in x for x in p)
    assert any(x.startswith("discount = 1.0") for x in p)


def test_names_of_a_model_and_a_task_are_checked_alike(model, task):
    """Trust levels and complexities, of a model and of a task, are distinct non-empty texts, at
    least two: one check says it everywhere (a number among the names was taken before)."""
    with pytest.raises(ModelError) as exc:
        model.replace(trust_levels=("low", 3))
    assert exc.value.problems == ["trust_levels must be a list of non-empty strings, got ['low', 3]"]
    with pytest.raises(ModelError) as exc:
        model.replace(complexities=("low", "low"))
    assert exc.value.problems == ["complexities has duplicate names: ['low', 'low']"]
    with pytest.raises(ModelError, match=r"complexities must be a list of non-empty strings, got \['low', 2\]"):
        dataclasses.replace(task, complexities=("low", 2))


def test_a_model_takes_its_tables_with_one_axis_per_input_only(model):
    """A table given by input combination, (U, K, ·), is refused with its expected shape (the
    constructor reshaped it before; only the fit's own conversion needs that form)."""
    with pytest.raises(ModelError, match=r"emission has shape \(4, 2, 2\), expected \(2, 2, 2, 2\)"):
        model.replace(emission=model.emission_rows)


def test_names_must_match(model, task):
    from trustseek import AssistancePOMDP

    other = Task.from_dict(json.loads(json.dumps(task.to_dict()).replace('"low"', '"easy"')))
    with pytest.raises(ModelError, match="differ from the task"):
        AssistancePOMDP(model, other)


def test_missing_and_bad_files(tmp_path):
    with pytest.raises(ModelError, match="file not found"):
        TrustModel.load(tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text("{ not json")
    with pytest.raises(ModelError, match=r"invalid JSON at line 1, column 3"):
        TrustModel.load(tmp_path / "bad.json")
    with pytest.raises(ModelError, match="unknown model preset"):
        load_model("papr")


# --------------------------------------------------------------------------- property-based


def _paths(d, prefix=()):
    """All (path, value) leaves and inner nodes of a nested dict."""
    for k, v in d.items():
        yield prefix + (k,), v
        if isinstance(v, dict):
            yield from _paths(v, prefix + (k,))


def _set(d, path, value):
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value


def _delete(d, path):
    for k in path[:-1]:
        d = d[k]
    del d[path[-1]]


PAPER = TrustModel.from_dict(load_model("paper").to_dict()).to_dict()
PROB_LEAVES = [p for p, v in _paths(PAPER) if isinstance(v, float) and p[0] in ("initial", "emission", "transition")]
NODES = [p for p, v in _paths(PAPER) if p[0] in ("initial", "emission", "transition", "trust_levels", "complexities")]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    mutation=st.sampled_from(["delete", "range", "sum", "type", "unknown", "nan"]),
    leaf=st.sampled_from(PROB_LEAVES),
    node=st.sampled_from(NODES),
    value=st.floats(min_value=1e-6, max_value=0.5),
)
def test_validation_catches_random_corruption(mutation, leaf, node, value):
    d = copy.deepcopy(PAPER)
    if mutation == "delete":
        _delete(d, node)
        expect = node[-1]
    elif mutation == "range":
        _set(d, leaf, 1.0 + value)
        expect = "outside [0, 1]"
    elif mutation == "sum":
        # shift one cell within [0, 1] so that the row no longer sums to one
        old = d
        for k in leaf:
            old = old[k]
        new = old - value if old - value >= 0 else old + value
        _set(d, leaf, new)
        expect = "sums to"
    elif mutation == "type":
        _set(d, leaf, "0.5")
        expect = "must be a number"
    elif mutation == "nan":
        _set(d, leaf, float("nan"))
        expect = "outside [0, 1]"
    else:
        _set(d, leaf[:-1] + ("bogus",), 0.0)
        expect = "unknown entry 'bogus'"
    with pytest.raises(ModelError) as exc:
        TrustModel.from_dict(d, "f.json")
    assert exc.value.problems, "a problem must be reported"
    assert any(expect in p for p in exc.value.problems), exc.value.problems
    # every problem line names where it is
    for line in exc.value.lines():
        assert line.startswith("f.json: ")


def _random_rows(draw, shape):
    k = shape[-1]
    n = int(np.prod(shape[:-1])) if len(shape) > 1 else 1
    raw = (
        np.array(draw(st.lists(st.floats(0.01, 1.0), min_size=n * k, max_size=n * k))).reshape(*shape[:-1], k)
        if len(shape) > 1
        else np.array(draw(st.lists(st.floats(0.01, 1.0), min_size=k, max_size=k)))
    )
    return raw / raw.sum(axis=-1, keepdims=True)


@st.composite
def random_models(draw):
    K = draw(st.integers(2, 4))
    N = draw(st.integers(2, 3))
    return trust_model(
        trust_levels=tuple(f"t{i}" for i in range(K)),
        complexities=tuple(f"c{i}" for i in range(N)),
        initial=_random_rows(draw, (K,)),
        emission=_random_rows(draw, (N, 2, K, 2)),
        transition=_random_rows(draw, (N, 2, 2, K, K)),
    )


@settings(max_examples=40, deadline=None)
@given(random_models())
def test_valid_random_models_round_trip(m):
    again = TrustModel.from_dict(json.loads(json.dumps(m.to_dict())))
    assert again == m


# --------------------------------------------------------------------------- never-estimated rows


def _no_ask_fit():
    from trustseek import paper_model
    from trustseek.estimation import fit_trust_model
    from trustseek.simulation.designs import simulate_design

    df = simulate_design(paper_model(), 40, seed=0, p_ask=(0.0, 0.0))  # a study in which the robot never asks
    return fit_trust_model(df, options=FitOptions(restarts=1, seed=0, tol=1e-5))


def test_not_estimated_round_trips_and_absent_means_all_estimated(tmp_path, model):
    assert model.not_estimated == () and "not_estimated" not in model.to_dict()
    marked = model.replace(not_estimated=(("transition", (1, 1, 1)), ("emission", (0, 1))))
    d = marked.to_dict()
    assert d["not_estimated"] == [
        {"table": "emission", "C": "low", "a": "ask"},
        {"table": "transition", "C": "high", "a": "ask", "E": "reliable"},
    ]
    marked.save(tmp_path / "m.json")
    back = TrustModel.load(tmp_path / "m.json")
    assert back == marked and back != model
    assert back.not_estimated_rows() == ["emission[C=low, a=ask]", "transition[C=high, a=ask, E=reliable]"]


def test_bad_not_estimated_entries_are_each_reported(model):
    d = model.to_dict()
    d["not_estimated"] = [
        {"table": "emission", "C": "medium", "a": "ask"},
        {"table": "prior"},
        {"table": "emission", "C": "low", "a": "ask", "E": "faulty"},
    ]
    with pytest.raises(ModelError) as exc:
        TrustModel.from_dict(d)
    text = str(exc.value)
    assert (
        "not_estimated[0]: C = 'medium'" in text and "not_estimated[1]" in text and "not_estimated[2]: unknown keys ['E']" in text
    )


def test_a_fit_without_asking_marks_the_ask_rows_and_planning_refuses_them(task):
    """Before the marker, the ask transitions of such a fit were unmarked identity rows and
    AssistancePOMDP planned with them silently."""
    from trustseek import paper_model
    from trustseek.pomdp.problem import AssistancePOMDP

    res = _no_ask_fit()
    rows = res.model.not_estimated_rows()
    assert rows == [f"transition[C={c}, a=ask, E={e}]" for c in ("low", "high") for e in ("faulty", "reliable")]
    assert any("never estimated" in w for w in res.warnings)
    with pytest.raises(ModelError) as exc:
        AssistancePOMDP(res.model, task)
    lines = exc.value.problems
    # only the rows the task reaches: asking records a faulty experience in low complexity, reliable in high
    assert [ln.split(" was")[0] for ln in lines[:-1]] == [
        "transition[C=low, a=ask, E=faulty]",
        "transition[C=high, a=ask, E=reliable]",
    ]
    assert "--fill-from paper" in lines[-1]
    filled = res.model.filled_from(paper_model())
    assert filled.not_estimated == ()
    np.testing.assert_array_equal(filled.transition[:, 1], paper_model().transition[:, 1])
    np.testing.assert_array_equal(filled.transition[:, 0], res.model.transition[:, 0])
    AssistancePOMDP(filled, task)


def test_a_fit_of_the_paper_design_plans_without_filling(task):
    from trustseek import paper_model
    from trustseek.estimation import fit_trust_model
    from trustseek.pomdp.problem import AssistancePOMDP
    from trustseek.simulation.designs import simulate_design

    res = fit_trust_model(simulate_design(paper_model(), 30, seed=1), options=FitOptions(restarts=1, seed=0, tol=1e-5))
    # the design never produces these (the experience after asking is fixed by the complexity)
    assert res.model.not_estimated_rows() == ["transition[C=low, a=ask, E=reliable]", "transition[C=high, a=ask, E=faulty]"]
    AssistancePOMDP(res.model, task)


def test_filling_needs_the_same_levels(model):
    three = load_model(str(__import__("trustseek.data.trials", fromlist=["x"]).example_path("three_level_model.json")))
    with pytest.raises(ModelError, match="cannot fill"):
        model.replace(not_estimated=(("emission", (0, 1)),)).filled_from(three)


def test_one_model_class_the_trust_model_is_its_configuration_with_the_paper_inputs(tmp_path):
    """A trust model and a general model are one class: the trust model is the general model with
    the paper's inputs and no fitted structure; either file is written again byte for byte, and a
    general model with the paper's inputs stays a general model file."""
    from importlib.resources import files

    from trustseek.model.core import load_any_model

    shipped = files("trustseek") / "examples" / "three_level_model.json"
    m = TrustModel.load(shipped)
    m.save(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_bytes() == shipped.read_bytes()
    assert not m.general and m.emission.shape == (2, 2, 3, 2) and m.emission_rows.shape == (4, 3, 2)
    general = m.replace(structure={"prior": 0.0})
    assert general.general and type(general) is type(m) and general != m
    general.save(tmp_path / "general.json")
    text = (tmp_path / "general.json").read_text()
    assert '"format": "trustseek.iohmm/1"' in text
    back = load_any_model(tmp_path / "general.json")
    assert back == general and back.emission.shape == m.emission.shape
    back.save(tmp_path / "general2.json")
    assert (tmp_path / "general2.json").read_text() == text
    with pytest.raises(ModelError, match="is not a trust model: planning"):
        TrustModel.load(tmp_path / "general.json")
    with pytest.raises(ModelError, match="not a trust model: planning"):
        _ = general.complexities
    with pytest.raises(ModelError, match="a trust model has the paper's inputs"):
        m.replace(emission_inputs=("complexity",), emission=m.emission[:, 0])
    with pytest.raises(ModelError, match="not_estimated marks rows of a trust model"):
        general.replace(not_estimated=(("emission", (0, 1)),))


@pytest.mark.parametrize("inputs", [None, 5, [["a"]], "abc"])
def test_a_general_model_file_with_broken_input_names_is_refused_for_planning(tmp_path, inputs):
    path = tmp_path / "general.json"
    path.write_text(json.dumps({"format": "trustseek.iohmm/1", "emission_inputs": inputs}), encoding="utf-8")
    with pytest.raises(ModelError, match=r"general\.json.*inputs: none\) is not a trust model"):
        TrustModel.load(path)
