"""The .pomdp and POMDPX exports against strict readers written from the published format
documents (tests/strict_pomdp_readers.py): they load unpatched, and the numbers they carry are
the model's (the flat kernel; the POMDPX joint equals P(C') P(o, E', T' | T, C, a))."""

from importlib import resources

import numpy as np
import pytest

from pomdp_oracles import ENTRY_FORMS, TIGER
from strict_pomdp_readers import StrictFormatError, pomdpx_transition, read_cassandra, read_pomdpx
from trustseek.interop.files import flat_from_assistance, pomdpx_factors, read_pomdp, write_pomdp, write_pomdpx
from trustseek.model.presets import load_model, load_task
from trustseek.pomdp.problem import AssistancePOMDP


def _three_level() -> AssistancePOMDP:
    ex = resources.files("trustseek") / "examples"
    return AssistancePOMDP(load_model(str(ex / "three_level_model.json")), load_task(str(ex / "three_level_task.json")))


@pytest.fixture(params=["paper", "three-level"])
def any_pomdp(request, pomdp):
    return pomdp if request.param == "paper" else _three_level()


# --------------------------------------------------------------------------- Cassandra .pomdp


def test_pomdp_export_loads_in_the_strict_reader_with_the_models_numbers(any_pomdp):
    flat = flat_from_assistance(any_pomdp)
    text = write_pomdp(flat)
    strict = read_cassandra(text)
    assert strict.states == list(flat.states) and strict.observations == list(flat.observations)
    assert strict.values == "reward" and strict.discount == flat.discount
    assert np.array_equal(strict.T, flat.transition) and np.array_equal(strict.O, flat.observation)
    assert np.array_equal(strict.start, flat.start)
    # the file writes each reward as R(a, s) for every next state and observation
    assert np.array_equal(strict.R, flat.reward)
    ours = read_pomdp("export.pomdp", text)
    assert np.array_equal(ours.transition, strict.T) and np.array_equal(ours.reward, strict.R)


def test_pomdp_writer_turns_any_names_into_identifiers():
    """Default numeric names are written as a count; other names become identifiers."""
    forms = read_pomdp("forms.pomdp", ENTRY_FORMS)  # states: 2 -> names '0', '1'
    strict = read_cassandra(write_pomdp(forms))
    assert strict.states == ["0", "1"] and np.array_equal(strict.T, forms.transition)
    tiger = read_pomdp("tiger.pomdp", TIGER)
    odd = type(tiger)(
        ("tiger.left", "2right"), ("listen", "open left", "reward"), ("obs.left", "obs_left"),
        tiger.transition, tiger.observation, tiger.reward, tiger.discount, tiger.start,
    )  # fmt: skip
    strict = read_cassandra(write_pomdp(odd))
    assert strict.states == ["tiger_left", "v2right"]
    assert strict.actions == ["listen", "open_left", "reward_"]
    assert strict.observations == ["obs_left_0", "obs_left_1"]
    assert np.array_equal(strict.R, tiger.reward)


def _paper_pomdp_text(pomdp) -> str:
    return write_pomdp(flat_from_assistance(pomdp))


@pytest.mark.parametrize(
    "edit,message",
    [
        # the old exporter's names: '.' is not an identifier character
        (lambda t: t.replace("low_faulty_low_intervene", "low.faulty.low.intervene"), "unexpected character '.'"),
        (lambda t: t.replace("discount: 0.987", "discount: 9.87e-1"), "malformed number starting '9.87e'"),
        (lambda t: t.replace("discount: 0.987", "discount: .987"), "unexpected character '.'"),
        (lambda t: t.replace("actions: autonomous ask", "actions: autonomous 2ask"), "malformed number starting '2a'"),
        (lambda t: t.replace("actions: autonomous ask", "actions: autonomous uniform"), "'uniform' is a keyword"),
        (lambda t: t.replace("\nstart: ", "\nT: ask : 0 : 0 1.0\nstart: "), "expected T:, O: or R:, got 'start'"),
        (lambda t: t.replace("values: reward\n", "") + "values: reward\n", "the preamble lacks 'values:'"),
        (
            lambda t: t.replace("\nT: autonomous\n0.0099 ", "\nT: autonomous\n0.0098 "),
            "T: autonomous : low_faulty_low_intervene sums to",
        ),
        (lambda t: t.replace("O: ask\n1.0", "O: ask\n-1.0", 1), "a probability has no sign"),
        (lambda t: t.replace("start: 0.0", "start: 0.5", 1), "start sums to"),
    ],
)
def test_strict_cassandra_reader_refuses_bad_files(pomdp, edit, message):
    good = _paper_pomdp_text(pomdp)
    read_cassandra(good)
    bad = edit(good)
    assert bad != good
    with pytest.raises(StrictFormatError) as exc:
        read_cassandra(bad)
    assert message in str(exc.value)


# --------------------------------------------------------------------------- POMDPX


def test_pomdpx_export_loads_in_the_strict_reader(any_pomdp):
    m = read_pomdpx(write_pomdpx(any_pomdp))
    assert m.discount == any_pomdp.discount
    observed = {prev[: -len("_0")]: full for prev, _, full in m.state_vars}
    assert observed == {"trust": False, "experience": True, "complexity": True, "human": False}
    assert m.variables["trust_1"].values == list(any_pomdp.trust_levels)
    init = m.tables["InitialStateBelief"]
    assert np.array_equal(init["trust_0"][1], any_pomdp.model.initial)
    assert np.array_equal(init["complexity_0"][1], any_pomdp.complexity_probs)
    assert init["experience_0"][0] == ["null"] and list(init["experience_0"][1]) == [0.0, 1.0]
    assert np.array_equal(m.tables["ObsFunction"]["human_action"][1], np.eye(2))


def test_pomdpx_joint_equals_the_models_kernel(any_pomdp):
    """The product of the CondProb tables, as the strict reader expands them, is
    P(C') P(o, E', T' | T, C, a) for every previous experience and human action."""
    m = read_pomdpx(write_pomdpx(any_pomdp))
    axes, joint = pomdpx_transition(m)
    assert axes == ["robot", "trust_0", "experience_0", "complexity_0", "human_0"] + [
        "trust_1",
        "experience_1",
        "complexity_1",
        "human_1",
    ]
    kern = any_pomdp.kernel  # [c, a, t, o, e, u]
    want = np.einsum("catoeu,d->atcuedo", kern, any_pomdp.complexity_probs)
    for e0 in range(2):
        for o0 in range(2):
            got = joint[:, :, e0, :, o0]  # [a, t, c, u, e', c', o]
            assert np.allclose(got, want, atol=1e-15)
    rparents, rtable = m.reward["reward"]
    assert rparents == ["robot", "complexity_0", "trust_0"]
    assert np.allclose(rtable, np.transpose(any_pomdp.expected_reward, (1, 0, 2)), atol=1e-12)


def test_pomdpx_factors_are_the_two_factorings_of_one_joint(pomdp):
    """P(E' | T, C, a) P(o | E', T, C, a) = P(o | T, C, a) P(E' | o, C, a) cell by cell."""
    f = pomdpx_factors(pomdp)
    lhs = f["experience"][..., None] * f["human"]  # [a, t, c, e, o]
    rhs = np.einsum("cato,caoe->atceo", pomdp.emission, pomdp.experience)
    assert np.allclose(lhs, rhs, atol=1e-15)
    # where an experience cannot follow (e.g. an ask in high complexity is never faulty), the
    # unreachable human row is P(o | T, C, a)
    never = f["experience"] == 0.0
    assert never.any()
    prior = np.broadcast_to(np.transpose(pomdp.emission, (1, 2, 0, 3))[:, :, :, None, :], f["human"].shape)
    assert np.array_equal(f["human"][never], prior[never])


def _swap_to_old_factoring(text: str) -> str:
    """The previous export: experience depended on the human action of the same trial."""
    return text.replace(
        "<Var>experience_1</Var>\n      <Parent>robot trust_0 complexity_0</Parent>",
        "<Var>experience_1</Var>\n      <Parent>robot trust_0 human_1</Parent>",
    )


@pytest.mark.parametrize(
    "edit,message",
    [
        # the old exporter's initial belief: two '-' for a null parent
        (
            lambda t: t.replace("<Instance>-</Instance>", "<Instance>- -</Instance>", 1),
            "trust_0: <Instance> '- -' has 2 tokens; a null parent takes one",
        ),
        # the old exporter's factoring: a fully observed variable with a same-slice parent
        (_swap_to_old_factoring, "experience_1 is fully observed, so it cannot have a parent in its own time slice"),
        (
            lambda t: t.replace(
                "<Parent>robot trust_0 complexity_0 experience_1</Parent>",
                "<Parent>robot trust_1 complexity_0 experience_1</Parent>",
            ),
            "human_1 is hidden, so its parents in its own time slice must be fully observed (trust_1 is not)",
        ),
        (
            lambda t: t.replace("<Parent>human_1</Parent>", "<Parent>human_0</Parent>"),
            "observation parents are the action and next-slice",
        ),
        (
            lambda t: t.replace("<Parent>robot</Parent>", "<Parent>null</Parent>"),
            "a 'null' parent is allowed only in the initial belief",
        ),
        (
            lambda t: t.replace("<ProbTable>0.5 0.5 0.5 0.5</ProbTable>", "<ProbTable>0.5 0.5 0.5</ProbTable>"),
            "the table has 3 numbers, the Instance enumerates 4",
        ),
        (lambda t: t.replace("<ProbTable>0.5 0.5 0.5 0.5</ProbTable>", "<ProbTable>0.5 0.5 0.5 0.4</ProbTable>"), "sums to"),
        (
            lambda t: t.replace(
                "<Instance>- -</Instance>\n          <ProbTable>0.5 0.5 0.5 0.5</ProbTable>",
                "<Instance>ask -</Instance>\n          <ProbTable>0.5 0.5</ProbTable>",
            ),
            "complexity_1: the entries leave cell (0, 0) unset",
        ),
        (lambda t: t.replace("<Instance>- -</Instance>", "<Instance>maybe -</Instance>", 1), "'maybe' is not a value"),
        (lambda t: t.replace('fullyObs="true"', 'fullyObs="yes"', 1), "fullyObs must be true or false"),
        (lambda t: t.replace("<Discount>0.987</Discount>", "<Discount>1.0</Discount>"), "outside [0, 1)"),
        (lambda t: t.replace("<Discount>0.987</Discount>", "<Discount>9.87e-1</Discount>"), "is not a decimal number"),
        (lambda t: t.replace("<ValueEnum>low high</ValueEnum>", "<ValueEnum>low low</ValueEnum>", 1), "distinct values"),
        (lambda t: t.replace("<Var>human_action</Var>", "<Var>human_0</Var>"), "must be a declared obs variable"),
    ],
)
def test_strict_pomdpx_reader_refuses_bad_files(pomdp, edit, message):
    good = write_pomdpx(pomdp)
    read_pomdpx(good)
    bad = edit(good)
    assert bad != good
    with pytest.raises(StrictFormatError) as exc:
        read_pomdpx(bad)
    assert message in str(exc.value)
