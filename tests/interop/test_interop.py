"""Standard POMDP files: Cassandra .pomdp round trips and errors, POMDPX tables, the augmented
export, and finite-horizon cross-checks against pomdp-py."""

import json
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from pomdp_oracles import ENTRY_FORMS, TIGER, pomdp_py_value
from trustseek.interop.files import (
    PomdpFileError,
    flat_belief,
    flat_from_assistance,
    read_pomdp,
    write_pomdp,
    write_pomdpx,
)
from trustseek.solvers.alpha import finite_horizon_value

pomdp_py = pytest.importorskip("pomdp_py")
from pomdp_py.algorithms import value_function  # noqa: E402

# --------------------------------------------------------------------------- .pomdp


def test_tiger_parses_with_wildcards_identity_and_uniform():
    f = read_pomdp("tiger.pomdp", TIGER)
    assert f.states == ("tiger-left", "tiger-right") and f.actions == ("listen", "open-left", "open-right")
    assert np.allclose(f.transition[0], np.eye(2)) and np.allclose(f.transition[1], 0.5)
    assert np.allclose(f.observation[0], [[0.85, 0.15], [0.15, 0.85]])
    assert np.allclose(f.expected_reward, [[-1, -1], [-100, 10], [10, -100]])
    assert np.allclose(f.start, 0.5) and f.discount == 0.95


def test_tiger_finite_horizon_values_match_pomdp_py():
    """pomdp-py's own Tiger problem (independent code) at horizons 1-3 vs our parser + recursion."""
    from pomdp_py.problems.tiger.tiger_problem import TigerAction, TigerProblem, TigerState

    f = read_pomdp("tiger.pomdp", TIGER)
    b0 = pomdp_py.Histogram({TigerState("tiger-left"): 0.5, TigerState("tiger-right"): 0.5})
    tp = TigerProblem(0.15, TigerState("tiger-left"), b0)
    ag = tp.agent
    S = [TigerState("tiger-left"), TigerState("tiger-right")]
    A = [TigerAction(n) for n in ("listen", "open-left", "open-right")]
    Z = list(ag.observation_model.get_all_observations())
    expected = {1: -1.0, 2: -1.95}
    for h in (1, 2, 3):
        ours = f.finite_horizon_value(f.start, h)
        models = ag.transition_model, ag.observation_model, ag.reward_model
        theirs = value_function.value({s: b0[s] for s in S}, S, A, Z, *models, 0.95, horizon=h)
        # pomdp-py's Tiger leaks 1e-9 of probability when listening; the values agree to ~1e-7
        assert ours == pytest.approx(theirs, abs=1e-6)
        assert ours == pytest.approx(pomdp_py_value(f, f.start, h), abs=1e-9)
        if h in expected:
            assert ours == pytest.approx(expected[h], abs=1e-12)


def test_pomdp_round_trip(tmp_path, pomdp):
    flat = flat_from_assistance(pomdp)
    path = tmp_path / "paper.pomdp"
    write_pomdp(flat, path)
    back = read_pomdp(path)
    assert back.states == flat.states and back.observations == flat.observations
    for name in ("transition", "observation", "reward", "start"):
        assert np.array_equal(getattr(back, name), getattr(flat, name)), name
    assert back.discount == flat.discount
    tiger = read_pomdp("t", TIGER)
    again = read_pomdp("t2", write_pomdp(tiger))
    assert np.array_equal(again.reward, tiger.reward) and np.array_equal(again.transition, tiger.transition)


@pytest.mark.parametrize(
    "text,message",
    [
        (TIGER.replace("T: open-left\nuniform", "T: open-left\n0.5 0.5"), "line 9: T matrix needs 4 numbers, got 2"),
        (
            TIGER.replace("O: listen\n0.85 0.15", "O: listen\n0.85 0.25"),
            "observation[listen, tiger-left] must be a probability row",
        ),
        (TIGER.replace("R: listen : * : * : * -1", "R: listen : tiger-middle : * : * -1"), "unknown state 'tiger-middle'"),
        (TIGER.replace("discount: 0.95", "discount: high"), "discount must be a number"),
        (TIGER.replace("states: tiger-left tiger-right\n", ""), "missing 'states:' header"),
    ],
)
def test_bad_pomdp_files_give_clear_errors(text, message):
    with pytest.raises(PomdpFileError) as exc:
        read_pomdp("bad.pomdp", text)
    assert message in str(exc.value)
    assert str(exc.value).startswith("bad.pomdp: ")


def test_error_names_the_line():
    with pytest.raises(PomdpFileError, match=r"line 21: unknown state 'nowhere'"):
        read_pomdp("bad.pomdp", TIGER.replace("R: open-left : tiger-left : * : * -100", "R: open-left : nowhere : * : * -100"))


# --------------------------------------------------------------------------- the augmented export


def test_export_matches_the_belief_mdp_at_horizons_1_to_3_via_pomdp_py(pomdp):
    """The flat file (human action moved into the next state) has the values of the belief MDP,
    computed by pomdp-py's exact recursion and by our two-level alpha recursion."""
    flat = flat_from_assistance(pomdp)
    for belief in (1.0, 0.4):
        for c in range(2):
            b = flat_belief(pomdp, belief, c)
            for h in (1, 2) if (belief, c) != (1.0, 1) else (1, 2, 3):
                ours = finite_horizon_value(pomdp, h, belief, c)
                assert flat.finite_horizon_value(b, h) == pytest.approx(ours, abs=1e-9)
                assert pomdp_py_value(flat, b, h) == pytest.approx(ours, abs=1e-6)


def read_pomdpx_tables(text: str) -> dict[str, tuple[list[str], np.ndarray]]:
    """The conditional tables of a POMDPX file written by :func:`write_pomdpx`: variable ->
    (parents, table with one axis per parent and a last axis for the variable)."""
    root = ET.fromstring(text)

    def words(elem: ET.Element, path: str) -> list[str]:
        found = elem.find(path)
        if found is None or found.text is None:
            raise AssertionError(f"POMDPX element <{elem.tag}> has no <{path}>")
        return found.text.split()

    sizes: dict[str | None, int] = {}
    for sv in root.iter("StateVar"):
        sizes[sv.get("vnamePrev")] = sizes[sv.get("vnameCurr")] = len(words(sv, "ValueEnum"))
    for tag in ("ObsVar", "ActionVar"):
        for v in root.iter(tag):
            sizes[v.get("vname")] = len(words(v, "ValueEnum"))
    out = {}
    for section in ("InitialStateBelief", "StateTransitionFunction", "ObsFunction"):
        for c in root.iter(section):
            for cp in c.iter("CondProb"):
                name = words(cp, "Var")[0]
                parents = words(cp, "Parent")
                shape = [sizes[p] for p in parents if p != "null"] + [sizes[name]]
                vals = np.array([float(x) for x in words(cp, "Parameter/Entry/ProbTable")])
                out[f"{section}/{name}"] = (parents, vals.reshape(shape))
    return out


def test_pomdpx_tables_reproduce_the_flat_transition(pomdp):
    tabs = read_pomdpx_tables(write_pomdpx(pomdp))
    for key, (_, table) in tabs.items():
        assert np.allclose(table.sum(axis=-1), 1.0), key
    exp = tabs["StateTransitionFunction/experience_1"][1]  # [a, t, c, e]
    human = tabs["StateTransitionFunction/human_1"][1]  # [a, t, c, e, o]
    trust = tabs["StateTransitionFunction/trust_1"][1]  # [a, c, e, t, u]
    cx = tabs["StateTransitionFunction/complexity_1"][1]  # [a, c2]
    joint = np.einsum("atce,atceo,acetu,ad->atcoeud", exp, human, trust, cx)
    flat = flat_from_assistance(pomdp)
    K, N = pomdp.n_trust, pomdp.n_complexity
    T = flat.transition.reshape(2, K, 2, N, 2, K, 2, N, 2)  # [a, t, e, c, o_prev, u, e2, c2, o]
    for e in range(2):
        for op in range(2):
            want = np.einsum("atcoeud->atcueod", joint)  # [a, t, c, u, e2, o, c2]
            got = T[:, :, e, :, op].transpose(0, 1, 2, 3, 4, 6, 5)  # [a, t, c, u, e2, o, c2]
            assert np.allclose(got, want)
    assert np.allclose(tabs["InitialStateBelief/trust_0"][1], pomdp.model.initial)


# --------------------------------------------------------------------------- CLI


def _run(*args):
    return subprocess.run([sys.executable, "-m", "trustseek", *args], capture_output=True, text=True, timeout=120)


def test_cli_export_and_solve_file(tmp_path):
    out = tmp_path / "paper.pomdp"
    proc = _run("export-pomdp", str(out), "--verify")
    assert proc.returncode == 0, proc.stderr
    assert "wrote" in proc.stdout and out.exists()
    assert read_pomdp(out).states[0] == "low_faulty_low_intervene"
    tiger = tmp_path / "tiger.pomdp"
    tiger.write_text(TIGER)
    proc = _run("solve-pomdp-file", str(tiger), "--json")
    d = json.loads(proc.stdout)
    assert d["lower"] <= d["upper"] and d["gap"] <= 1e-3
    assert d["lower"] == pytest.approx(19.3714, abs=1e-3)


def test_cli_bad_file_one_line_exit_2(tmp_path):
    bad = tmp_path / "bad.pomdp"
    bad.write_text(TIGER.replace("0.85 0.15\n0.15 0.85", "0.85 0.15\n0.15"))
    proc = _run("solve-pomdp-file", str(bad))
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "O matrix needs 4 numbers, got 3" in proc.stderr


def test_cli_solve_with_alpha_and_point_json():
    proc = _run("solve", "--solver", "alpha", "--belief-update", "paper", "--json")
    assert proc.returncode == 0, proc.stderr
    d = json.loads(proc.stdout)
    assert d["certified_gap"] <= 1e-6
    lo, hi = d["threshold_intervals"]["high"]
    assert lo <= d["thresholds"]["high"] <= hi
    proc = _run("solve", "--solver", "point", "--belief-update", "paper")
    assert proc.returncode == 2 and "Bayes filter" in proc.stderr


def test_entry_forms_rows_single_entries_indices_and_costs():
    text = ENTRY_FORMS
    f = read_pomdp("forms.pomdp", text)
    assert f.states == ("0", "1") and np.array_equal(f.start, [0.0, 1.0])
    assert np.array_equal(f.transition[0], [[0, 1], [0, 1]]) and np.array_equal(f.transition[1], [[1, 0], [0, 1]])
    assert np.array_equal(f.observation[0], [[0.25, 0.75], [0.5, 0.5]])
    assert np.array_equal(f.observation[1], [[0.25, 0.75], [0.25, 0.75]])
    assert np.array_equal(f.reward[0, 0, 1], [-4.0, -6.0])  # costs are negated rewards
    assert np.all(f.reward[1] == -1.0)
    # expected reward of 'go' in state 0: next state 1, observation beep 0.5 / quiet 0.5
    assert f.expected_reward[0, 0] == pytest.approx(-5.0)
