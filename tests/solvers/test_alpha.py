"""Alpha-vector solver: envelopes, exact backups, certified bounds and thresholds (two trust levels)."""

import json

import numpy as np
import pytest

from trustseek import AssistancePOMDP, BayesUpdate, GridSolver, PolicyRunner, load_policy
from trustseek.policies import AlphaVectorPolicy
from trustseek.policies.envelope import envelope, envelope_values
from trustseek.solvers.alpha import AlphaSolver, exact_backup, finite_horizon_value, finite_horizon_vectors
from trustseek.solvers.certified import residual_pieces

# Reference values from three independent solvers, Bayes update, paper preset
REF_V0, REF_V1_LOW, REF_V1_HIGH, REF_THRESHOLD, REF_MYOPIC = 110.655, 111.061, 110.249, 0.7815, 0.836


@pytest.fixture(scope="module")
def paper_pomdp():
    from trustseek import paper_model, paper_task

    return AssistancePOMDP(paper_model(), paper_task())


@pytest.fixture(scope="module")
def bayes(paper_pomdp):
    return AlphaSolver(belief_update="bayes", tol=1e-6).solve_bounds(paper_pomdp)


@pytest.fixture(scope="module")
def paper_update(paper_pomdp):
    return AlphaSolver(belief_update="paper", tol=1e-6).solve_bounds(paper_pomdp)


def test_envelope_matches_brute_force_maximum(rng):
    for _ in range(20):
        vecs = rng.normal(size=(rng.integers(1, 30), 2))
        idx, xs = envelope(vecs)
        assert xs[0] == 0.0 and xs[-1] == 1.0 and np.all(np.diff(xs) > 0)
        x = rng.random(500)
        brute = (np.stack([1 - x, x], axis=1) @ vecs.T).max(axis=1)
        assert np.allclose(envelope_values(vecs[idx], xs, x), brute, atol=1e-12)


def _bellman_at(pomdp, L, x):
    """Direct Bellman backup W(x) = Σ_C P(C) max_a [r + γ Σ_(o, E') P(o, E' | x) L(x')] with the
    core Bayes filter for x' and the branch probabilities from the emission and experience tables
    (independent of the solvers' branch kernels)."""
    upd = BayesUpdate(pomdp.model)
    b = np.stack([1 - x, x], axis=1)
    n = len(x)
    out = np.zeros(n)
    for c in range(pomdp.n_complexity):
        q = []
        for a in range(2):
            v = b @ pomdp.expected_reward[c, a]
            for o in range(2):
                for e in range(2):
                    w = (b @ pomdp.emission[c, a, :, o]) * pomdp.experience[c, a, o, e]
                    nb = upd.update(b, np.full(n, c), np.full(n, a), np.full(n, o), np.full(n, e))
                    v = v + pomdp.discount * w * L(nb[:, 1])
            q.append(v)
        out += pomdp.complexity_probs[c] * np.maximum(q[0], q[1])
    return out


def test_exact_backup_equals_direct_bellman_backup(paper_pomdp, rng):
    vecs = rng.normal(size=(12, 2)) * 10 + 100
    idx, xs = envelope(vecs)
    bk = exact_backup(paper_pomdp, vecs[idx], xs)
    x = np.concatenate([rng.random(400), [0.0, 1.0]])
    direct = _bellman_at(paper_pomdp, lambda z: envelope_values(vecs[idx], xs, z), x)
    assert np.allclose(envelope_values(bk.vectors, bk.xs, x), direct, atol=1e-9)


def test_finite_horizon_values_match_enumeration_with_the_core_filter(paper_pomdp):
    upd = BayesUpdate(paper_pomdp.model)
    K = paper_pomdp.kernel

    def v(b, c, h):  # exact recursion over (o, E') branches with the core Bayes filter
        if h == 0:
            return 0.0
        best = -np.inf
        for a in range(2):
            q = float(b @ paper_pomdp.expected_reward[c, a])
            if h > 1:
                for o in range(2):
                    for e in range(2):
                        p = float(b @ K[c, a, :, o, e, :].sum(axis=1))
                        if p > 0:
                            nb = upd.update(b, c, a, o, e)
                            q += (
                                paper_pomdp.discount
                                * p
                                * sum(pc * v(nb, c2, h - 1) for c2, pc in enumerate(paper_pomdp.complexity_probs))
                            )
            best = max(best, q)
        return best

    for h in (1, 2, 3):
        for belief in (1.0, 0.6, 0.2):
            b = np.array([1 - belief, belief])
            for c in range(2):
                assert finite_horizon_value(paper_pomdp, h, belief, c) == pytest.approx(v(b, c, h), abs=1e-10)


def test_myopic_threshold_is_0836(paper_pomdp):
    vecs = finite_horizon_vectors(paper_pomdp, 0)[-1]
    q = exact_backup(paper_pomdp, vecs).q[1]  # high complexity, one trial
    x = np.linspace(0, 1, 100001)
    d = envelope_values(*q[1], x) - envelope_values(*q[0], x)
    assert x[np.argmax(d <= 0)] == pytest.approx(REF_MYOPIC, abs=5e-4)


def test_bayes_reference_values_with_certified_gap(paper_pomdp, bayes):
    assert bayes.gap <= 1e-6
    q1 = bayes.q_values(paper_pomdp, np.array(1.0))
    assert q1[0].max() == pytest.approx(REF_V1_LOW, abs=5e-4)
    assert q1[1].max() == pytest.approx(REF_V1_HIGH, abs=5e-4)
    assert float(q1.max(axis=-1) @ paper_pomdp.complexity_probs) == pytest.approx(REF_V0, abs=5e-4)
    rep = bayes.threshold_report(paper_pomdp)
    assert rep["low"]["threshold"] is None
    th, (lo, hi) = rep["high"]["threshold"], rep["high"]["interval"]
    assert th == pytest.approx(REF_THRESHOLD, abs=1e-4)
    assert lo <= th <= hi and hi - lo < 1e-4


def test_certified_bounds_contain_the_grid_solution_and_grid_converges(paper_pomdp, bayes):
    x = np.linspace(0, 1, 201)
    lower = bayes.value(paper_pomdp, x)
    errors = []
    for G in (101, 401, 1601):
        sol = GridSolver(grid=G, belief_update="bayes").solve_grid(paper_pomdp)
        w = np.interp(x, sol.grid, sol.value @ paper_pomdp.complexity_probs)
        # the grid value over-estimates the convex value: it must not fall below the lower bound
        assert np.all(w >= lower - 1e-7)
        errors.append(float(np.max(w - lower)))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 1e-3


def test_certified_upper_bound_lies_above_value_iteration_on_a_fine_grid(paper_pomdp, bayes):
    """The upper bound lower + gap against an independent evaluation: exact Bellman backups
    T^k L of the certified lower bound L rise monotonically towards the value W, so on a fine
    belief grid every iterate must stay at or below the upper bound (a gap that under-states
    the error fails here), and must not fall below L (L is certified: T L >= L)."""
    x = np.linspace(0, 1, 20001)
    lower = bayes.value(paper_pomdp, x)
    upper = lower + bayes.gap
    vecs, xs = bayes.lower
    shift = bayes.residuals[1] / (1 - paper_pomdp.discount)
    v = np.asarray(vecs, dtype=float) - shift  # alpha vectors of L: values at P(high) = 0 and 1
    assert envelope_values(v, xs, x) == pytest.approx(lower, abs=1e-12)
    prev = lower
    rise = 0.0
    for _ in range(25):
        b = exact_backup(paper_pomdp, v)
        v = b.vectors
        cur = envelope_values(v, b.xs, x)
        assert np.all(cur >= prev - 1e-9)
        assert np.all(cur <= upper + 1e-9)
        rise = float(np.max(cur - lower))
        prev = cur
    # the backups do rise above L (by ~1e-8 here): a gap of zero, or one below that rise, fails the loop above
    assert 1e-9 < rise <= bayes.gap + 1e-9


def test_alpha_vector_policy_thresholds_json_and_runner(paper_pomdp, tmp_path):
    pol = AlphaSolver(tol=1e-6).solve(paper_pomdp)
    assert isinstance(pol, AlphaVectorPolicy)
    th = pol.thresholds()["high"]
    assert th == pytest.approx(REF_THRESHOLD, abs=1e-4)
    assert pol.thresholds()["low"] is None
    assert pol.action(th - 1e-4, "high") == 1 and pol.action(th + 1e-4, "high") == 0
    assert pol.action(0.0, "low") == 0
    path = tmp_path / "alpha.json"
    pol.save(path)
    back = load_policy(path)
    assert isinstance(back, AlphaVectorPolicy)
    assert back.thresholds()["high"] == pytest.approx(th, abs=1e-12)
    assert json.loads(path.read_text())["info"]["certified_gap"] <= 1e-6
    runner = PolicyRunner(back, rng=np.random.default_rng(0))
    assert runner.decide("high") == "autonomous"  # b0 = 1
    runner.observe("high", "autonomous", "intervene", "faulty")
    assert runner.decide("high") == "ask"


def test_paper_update_certified(paper_pomdp, paper_update):
    assert paper_update.gap <= 1e-6
    eps_plus, eps_minus = paper_update.residuals
    grid, values = paper_update.grid_solution
    # recomputing the exact residual on the returned grid gives the same certificate
    assert residual_pieces(paper_pomdp, grid, values)[:2] == pytest.approx((eps_plus, eps_minus), abs=1e-12)
    rep = paper_update.threshold_report(paper_pomdp)
    th, (lo, hi) = rep["high"]["threshold"], rep["high"]["interval"]
    assert lo <= th <= hi and hi - lo < 1e-4
    core = GridSolver(grid=2001, belief_update="paper").solve(paper_pomdp).thresholds()["high"]
    assert th == pytest.approx(core, abs=1e-4)
    # the eq.-3 value is not convex in general, but it is certified: the core grid sits inside
    v = paper_update.value(paper_pomdp, np.array([0.0, 0.5, 1.0]))
    sol = GridSolver(grid=2001, belief_update="paper").solve_grid(paper_pomdp)
    w = np.interp([0.0, 0.5, 1.0], sol.grid, sol.value @ paper_pomdp.complexity_probs)
    assert np.all(np.abs(w - v) < 1e-3)


def test_paper_residual_is_exact_on_a_coarse_grid(paper_pomdp):
    """The piecewise-quadratic supremum equals a brute-force maximum on a very fine sample."""
    from trustseek.solvers.certified import paper_q

    sol = GridSolver(grid=41, belief_update="paper").solve_grid(paper_pomdp)
    values = sol.value @ paper_pomdp.complexity_probs
    eps_plus, eps_minus = residual_pieces(paper_pomdp, sol.grid, values)[:2]
    x = np.linspace(0, 1, 400001)
    tv = paper_q(paper_pomdp, values, x, sol.grid).max(axis=1).T @ paper_pomdp.complexity_probs
    diff = tv - np.interp(x, sol.grid, values)
    assert diff.max() <= eps_plus + 1e-12 and -diff.min() <= eps_minus + 1e-12
    assert diff.max() == pytest.approx(eps_plus, abs=1e-7)
    assert -diff.min() == pytest.approx(eps_minus, abs=1e-7)


def test_alpha_needs_two_trust_levels():
    from trustseek.data import example_path
    from trustseek.model.core import TrustModel
    from trustseek.model.task import Task

    model = TrustModel.load(example_path("three_level_model.json"))
    p3 = AssistancePOMDP(model, Task.load(example_path("three_level_task.json")))
    with pytest.raises(ValueError, match="two trust levels"):
        AlphaSolver().solve(p3)


def test_controller_values_satisfy_the_controller_bellman_equations(paper_pomdp, rng):
    """Random controllers (some branches without successor), small and large enough for the
    iterative solve: α[n] = Σ_C P(C) (r(C, a) + γ Σ_(o, E') M α[succ]) node by node."""
    from trustseek.solvers.numerics import evaluate_controller

    K, R, pc, gamma = paper_pomdp.kernel, paper_pomdp.expected_reward, paper_pomdp.complexity_probs, paper_pomdp.discount
    for n in (1, 40, 700):
        acts = rng.integers(0, 2, size=(n, 2))
        succ = rng.integers(-1, n, size=(n, 2, 2, 2))
        model = paper_pomdp.branch_model()
        alpha = evaluate_controller(model, acts, succ.reshape(n, 2, 4), guess=np.full((n, 2), 100.0), rtol=1e-13)
        for i in rng.choice(n, size=min(n, 25), replace=False):
            v = np.zeros(2)
            for c in range(2):
                a = acts[i, c]
                v += pc[c] * R[c, a]
                for o in range(2):
                    for e in range(2):
                        if succ[i, c, o, e] >= 0:
                            v += gamma * pc[c] * K[c, a, :, o, e, :] @ alpha[succ[i, c, o, e]]
            assert np.allclose(v, alpha[i], atol=1e-9)


def test_paper_grid_values_match_the_core_policy_iteration(paper_pomdp, rng):
    """The eq.-3 grid MDP solved here equals the core's Howard iteration on the same
    non-uniform grid (transition matrices assembled independently, as scipy matrices)."""
    import scipy.sparse as sp

    from trustseek.solvers.certified import paper_grid_values, paper_maps
    from trustseek.solvers.grid import policy_iteration

    grid = np.unique(np.concatenate([[0.0, 1.0], rng.random(300)]))
    p, f = paper_maps(paper_pomdp)
    R, G = paper_pomdp.expected_reward, len(grid)
    r = R[:, :, 0, None] * (1 - grid) + R[:, :, 1, None] * grid
    P = [[None, None], [None, None]]
    for c in range(2):
        for a in range(2):
            m = sp.csr_matrix((G, G))
            for e in range(2):
                w = p[c, a, e, 0] * (1 - grid) + p[c, a, e, 1] * grid
                nx = f[c, a, e, 0] * (1 - grid) + f[c, a, e, 1] * grid
                m = m + sp.diags(w) @ sp.csr_matrix(_interp_rows(grid, nx))
            P[c][a] = m.tocsr()
    expected, _, _ = policy_iteration(r, P, paper_pomdp.complexity_probs, paper_pomdp.discount)
    assert np.allclose(paper_grid_values(paper_pomdp, grid), expected, atol=1e-9)
    assert np.allclose(paper_grid_values(paper_pomdp, grid, expected + 1e-3), expected, atol=1e-9)


def _interp_rows(grid, nx):
    """Dense rows of linear-interpolation weights of the points nx on the grid."""
    W = np.zeros((len(nx), len(grid)))
    for i, z in enumerate(nx):
        j = min(max(int(np.searchsorted(grid, z, side="right")) - 1, 0), len(grid) - 2)
        t = (z - grid[j]) / (grid[j + 1] - grid[j])
        W[i, j], W[i, j + 1] = 1 - t, t
    return W
