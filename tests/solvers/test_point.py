"""Point-based solver: Freudenthal interpolation, bounds on known problems, agreement with alpha/grid."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import trustseek
from pomdp_oracles import TIGER
from trustseek import AssistancePOMDP, GridSolver
from trustseek.interop.files import read_pomdp
from trustseek.model.core import TrustModel, trust_model
from trustseek.model.task import Task
from trustseek.policies import AlphaVectorPolicy
from trustseek.solvers.alpha import AlphaSolver
from trustseek.solvers.numerics import best_vectors
from trustseek.solvers.point import PointSolver, _simplex_lattice, freudenthal_weights, next_round_seconds

EXAMPLES = Path(trustseek.__file__).parent / "examples"


@pytest.mark.parametrize("K,r", [(2, 7), (3, 5), (4, 3)])
def test_freudenthal_weights_interpolate_linear_functions(rng, K, r):
    B = rng.dirichlet(np.ones(K), size=300)
    B = np.vstack([B, np.eye(K), _simplex_lattice(K, r)])
    verts, w = freudenthal_weights(B, r)
    assert np.all(w >= -1e-12) and np.allclose(w.sum(axis=1), 1.0)
    # vertex coordinates back to beliefs: b_i = (v_i - v_{i+1}) / r
    vb = (verts - np.concatenate([verts[..., 1:], np.zeros(verts.shape[:-1] + (1,), dtype=int)], axis=-1)) / r
    rebuilt = np.einsum("nk,nkt->nt", w, vb)
    assert np.allclose(rebuilt, B, atol=1e-12)
    # every vertex with positive weight is a lattice point of the simplex
    used = vb[w > 1e-12]
    assert np.all(used >= -1e-12) and np.allclose(used.sum(axis=1), 1.0)


def _tiger_grid_value(flat, G=4001, iters=2000):
    """An independent belief-grid value iteration for two-state Tiger (linear interpolation)."""
    x = np.linspace(0, 1, G)
    b = np.stack([1 - x, x], axis=1)
    r = flat.expected_reward
    M = flat.branch_kernels
    W = np.zeros(G)
    for _ in range(iters):
        q = []
        for a in range(3):
            v = b @ r[a]
            for o in range(2):
                nb = b @ M[a, o]
                p = nb.sum(axis=1)
                v = v + flat.discount * p * np.interp(nb[:, 1] / np.where(p > 0, p, 1), x, W)
            q.append(v)
        W_new = np.max(q, axis=0)
        if np.max(np.abs(W_new - W)) < 1e-12:
            break
        W = W_new
    return float(np.interp(0.5, x, W))


def test_tiger_bounds_bracket_an_independent_grid_value():
    flat = read_pomdp("tiger.pomdp", TIGER)
    sol = PointSolver(tol=1e-4).solve_bounds(flat)
    assert sol.gap <= 1e-4
    ref = _tiger_grid_value(flat)  # an upper bound (convex value), accurate to ~1e-5
    assert sol.lower <= ref + 1e-9
    assert ref == pytest.approx(sol.upper, abs=1e-4)
    assert sol.lower == pytest.approx(19.3714, abs=1e-3)  # the published Tiger value (γ = 0.95)


def test_paper_model_point_agrees_with_alpha_and_grid(pomdp):
    pol = PointSolver(tol=1e-4).solve(pomdp)
    assert isinstance(pol, AlphaVectorPolicy)
    lo, hi = pol.info["value_bounds_at_initial_belief"]
    assert hi - lo <= 1e-4
    alpha = AlphaSolver(tol=1e-6).solve(pomdp)
    a_lo, a_hi = alpha.info["value_bounds_at_initial_belief"]
    assert lo <= a_hi + 1e-9 and a_lo <= hi + 1e-9  # the certified intervals intersect
    grid = GridSolver(grid=2001).solve(pomdp)
    th = {"point": pol.thresholds()["high"], "alpha": alpha.thresholds()["high"], "grid": grid.thresholds()["high"]}
    assert max(th.values()) - min(th.values()) < 0.005
    for b in (1.0, 0.5, 0.0):
        vp, va, vg = pol.q_values(b).max(-1), alpha.q_values(b).max(-1), grid.q_values(b).max(-1)
        assert np.all(np.abs(vp - va) < 1e-3) and np.all(np.abs(vg - va) < 1e-3)


def test_lumped_three_level_model_has_the_two_level_value(model, task, pomdp):
    """Split 'high' trust into two identical levels: the value from (0, 1/2, 1/2) must equal the
    two-level value at b = 1 (the hidden chain is lumpable)."""
    N = model.n_complexity
    em = np.concatenate([model.emission, model.emission[:, :, 1:]], axis=2)  # high2 acts like high
    tr2 = model.transition
    tr3 = np.zeros((N, 2, 2, 3, 3))
    for src, s2 in ((0, 0), (1, 1), (2, 1)):
        tr3[..., src, 0] = tr2[..., s2, 0]
        tr3[..., src, 1] = 0.5 * tr2[..., s2, 1]
        tr3[..., src, 2] = 0.5 * tr2[..., s2, 1]
    m3 = trust_model(("low", "high", "high2"), model.complexities, np.array([0.0, 0.5, 0.5]), em, tr3)
    sol = PointSolver(tol=1e-3).solve_bounds(AssistancePOMDP(m3, task))
    ref = AlphaSolver(tol=1e-6).solve_bounds(pomdp)
    v = float(ref.q_values(pomdp, np.array(1.0)).max(axis=-1) @ task.complexity_probs)
    assert sol.gap <= 1e-3
    assert sol.lower - 1e-6 <= v <= sol.upper + 1e-6


def test_three_level_example_solves_with_reported_gap(tmp_path):
    m = TrustModel.load(EXAMPLES / "three_level_model.json")
    t = Task.load(EXAMPLES / "three_level_task.json")
    assert m.trust_levels == ("low", "medium", "high")
    pol = PointSolver(tol=1e-3).solve(AssistancePOMDP(m, t))
    lo, hi = pol.info["value_bounds_at_initial_belief"]
    assert 0 <= hi - lo <= 1e-3 and pol.info["certified_gap"] == pytest.approx(hi - lo)
    # sensible behaviour: never ask in low complexity at high trust; ask in high complexity at low trust
    assert pol.action(np.array([0.0, 0.0, 1.0]), "low") == 0
    assert pol.action(np.array([1.0, 0.0, 0.0]), "high") == 1
    assert pol.action(np.array([0.0, 0.0, 1.0]), "high") == 0
    # the lower bound at b0 is the value of the greedy vectors
    assert (pol.value_vectors @ m.initial).max() == pytest.approx(lo, abs=1e-9)
    # the policy file round-trips and decides the same way
    from trustseek import load_policy

    pol.save(tmp_path / "p3.json")
    back = load_policy(tmp_path / "p3.json")
    B = np.random.default_rng(3).dirichlet(np.ones(3), size=200)
    cx = np.arange(200) % 2
    assert np.array_equal(back.actions(B, cx), pol.actions(B, cx))


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(0, 120),
    K=st.integers(2, 5),
    m=st.integers(1, 25),
    rows=st.integers(1, 50),
    seed=st.integers(0, 2**32 - 1),
)
def test_best_vectors_in_blocks_is_the_argmax_of_the_whole_product(n, K, m, rows, seed):
    rng = np.random.default_rng(seed)
    X = rng.dirichlet(np.ones(K), size=n) if n else np.zeros((0, K))
    G = rng.normal(size=(m, K)).round(1)  # rounded: ties, which argmax breaks by the first index
    got = best_vectors(X, G, rows=rows)
    assert got.dtype == np.intp and got.shape == (n,)
    if n:
        assert np.array_equal(got, (X @ G.T).argmax(axis=1))


def test_next_round_time_grows_with_the_part_that_grows():
    # K = 4 at resolution 8 (lattice of the lower bound 6): the vertices grow 5.9x, the lower
    # bound's beliefs not at all
    assert next_round_seconds(4, 8, 6, t_upper=0.0, t_lower=0.45) == pytest.approx(0.45)
    assert next_round_seconds(4, 8, 6, t_upper=1.0, t_lower=0.0) == pytest.approx(969 / 165)
    # two states: the lower bound's lattice doubles with the grid until it stops at 256
    assert next_round_seconds(2, 64, 256, t_upper=0.0, t_lower=1.0) == pytest.approx(129 / 65)
    assert next_round_seconds(2, 256, 256, t_upper=0.0, t_lower=1.0) == pytest.approx(1.0)


def test_a_time_limit_is_used_when_the_rounds_are_cheaper_than_the_vertex_growth(monkeypatch):
    """On a fake clock where the upper bound costs 10 us per grid vertex and the lower bound 0.45 s
    a round (as measured on two supervisor types), a 5 s limit reaches the finest grid (64) in
    about 2.5 s.  Predicting the next round as (vertex growth) x the whole last round stopped
    at resolution 16 after 0.9 s."""
    from trustseek.model import paper_conservative_mixture, paper_task
    from trustseek.pomdp.supervisor_types import type_aware_problem
    from trustseek.solvers import point as point_module

    clock = [0.0]

    class FakeTime:
        @staticmethod
        def perf_counter() -> float:
            return clock[0]

    monkeypatch.setattr(point_module, "time", FakeTime)
    solver = PointSolver(tol=1e-9, max_seconds=5.0)
    upper, lower = solver._upper, solver._improve_lower

    def timed_upper(r):
        out = upper(r)
        clock[0] += 1e-5 * len(out[0])
        return out

    def timed_lower(*args, **kwargs):
        lower(*args, **kwargs)
        clock[0] += 0.45

    monkeypatch.setattr(solver, "_upper", timed_upper)
    monkeypatch.setattr(solver, "_improve_lower", timed_lower)
    sol = solver.solve_bounds(type_aware_problem(paper_conservative_mixture(), paper_task()))
    assert solver.grid_resolution == 64
    assert [len(h) for h in sol.history] == [4] * 4 and sol.history[-1][1] < 5.0
