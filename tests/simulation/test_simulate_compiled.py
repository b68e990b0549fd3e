"""The compiled simulation kernel against the numpy loop it replaces: the same simulation, bit for bit."""

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek import TrustModel, paper_model, paper_task, trust_model
from trustseek.policies import ComplexityPolicy, TrustAwarePolicy, ask_bounds
from trustseek.simulation import Block, Supervisors, crossover, kernels, run, schedule_counts, simulate

TASK = paper_task()


def test_a_simulation_runs_compiled_without_numba():
    """The kernels are built with the package: a one-off simulation runs them (nothing compiles at
    run time) and never loads numba."""
    code = (
        "import sys\nfrom unittest import mock\nfrom trustseek import paper_model, paper_task\n"
        "from trustseek.policies import ComplexityPolicy\nfrom trustseek.simulation import kernels, simulate\n"
        "t = paper_task()\nwith mock.patch.object(kernels, 'run_block', wraps=kernels.run_block) as block:\n"
        "    simulate(paper_model(), t, ComplexityPolicy('randomized', t.complexities, [0.1, 0.4]), 100, counts=(17, 17))\n"
        "print(block.call_count > 0, 'numba' in sys.modules, kernels.__file__.endswith('.so'))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.split() == ["True", "False", "True"]


def interior_model(seed: int) -> TrustModel:
    """Two trust levels, every probability inside (0, 1) (asked supervisors may rely, so that
    the human action after an ask carries information too)."""
    rng = np.random.default_rng(seed)
    em = rng.uniform(0.1, 0.9, size=(2, 2, 2))
    transition = rng.dirichlet([2.0, 2.0], size=(2, 2, 2, 2)) * 0.9 + 0.05
    return trust_model(("low", "high"), ("low", "high"), rng.dirichlet([3.0, 3.0]), np.stack([em, 1 - em], -1), transition)


def threshold_policy(model: TrustModel, bounds: tuple[float, float], update: str) -> TrustAwarePolicy:
    """A grid-Q policy that asks below ``bounds[C]`` (Q(ask) - Q(autonomous) = bound - x)."""
    grid = np.linspace(0.0, 1.0, 51)
    q = np.zeros((len(grid), 2, 2))
    for c, th in enumerate(bounds):
        q[:, c, 1] = th - grid
    return TrustAwarePolicy(grid, q, model, TASK.complexities, update)


def middle_policy(model: TrustModel) -> TrustAwarePolicy:
    """Asks only for beliefs in the middle: no threshold form (the numpy loop runs it)."""
    grid = np.linspace(0.0, 1.0, 51)
    q = np.zeros((len(grid), 2, 2))
    q[:, :, 1] = (0.09 - (grid - 0.5) ** 2)[:, None]
    return TrustAwarePolicy(grid, q, model, TASK.complexities, "bayes")


probability = st.sampled_from([0.0, 1.0, 0.3, 0.75])


@st.composite
def blocks(draw, n: int, model: TrustModel) -> list[Block]:
    out = []
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["threshold", "complexity", "middle"]))
        update = draw(st.sampled_from(["paper", "bayes"]))
        if kind == "threshold":
            bounds = tuple(draw(st.sampled_from([-0.1, 0.2, 0.5, 0.8, 1.2])) for _ in range(2))
            policy = threshold_policy(model, bounds, update)
        elif kind == "complexity":
            policy = ComplexityPolicy("randomized", TASK.complexities, [draw(probability), draw(probability)])
        else:
            policy = middle_policy(model)
        T = draw(st.integers(1, 12))
        sched = np.random.default_rng(draw(st.integers(0, 99))).integers(0, 2, size=(n, T)).astype(np.int8)
        tracked = draw(st.booleans())
        out.append(Block(policy, sched, belief_update=update if tracked else None, belief_model=model if tracked else None))
    return out


def assert_same(a, b) -> None:
    assert a.arrays is None or set(a.arrays) == set(b.arrays)
    for k, v in (a.arrays or {}).items():
        np.testing.assert_array_equal(v, b.arrays[k], err_msg=k)
    for k, v in a.summary_arrays.items():
        np.testing.assert_array_equal(v, b.summary_arrays[k], err_msg=k)


@settings(max_examples=60, deadline=None)
@given(data=st.data(), n=st.integers(1, 25), seed=st.integers(0, 2**32 - 1), pooled=st.booleans(), record=st.booleans())
def test_compiled_blocks_equal_the_numpy_loop(data, n, seed, pooled, record):
    model = interior_model(data.draw(st.integers(0, 50)))
    sup = Supervisors.pooled(model, n) if pooled else Supervisors.from_models([model, interior_model(seed % 7 + 60)], n)
    bl = data.draw(blocks(n, model))
    a = run(TASK, sup, bl, seed=seed, record=record)
    b = run(TASK, sup, bl, seed=seed, record=record, compiled=False)
    assert_same(a, b)


def test_the_kernel_runs_the_common_cases(monkeypatch):
    calls = []
    inner = kernels.run_block

    def counting(*args):
        calls.append(args[2][0])  # the policy's mode
        return inner(*args)

    monkeypatch.setattr(kernels, "run_block", counting)
    model = paper_model()
    policy = threshold_policy(model, (-np.inf, 0.7), "paper")
    assert ask_bounds(policy) is not None
    randomized = ComplexityPolicy("randomized", TASK.complexities, [0.1, 0.4])
    simulate(model, TASK, randomized, 3, counts=(4, 3))
    crossover(model, TASK, [policy, ComplexityPolicy("trust-agnostic", TASK.complexities, [0.0, 1.0])], 4, seed=1)
    simulate(model, TASK, middle_policy(model), 3, counts=(4, 3))  # no threshold form: the numpy loop
    assert calls == [kernels.FIXED, kernels.THRESHOLD, kernels.FIXED, kernels.FIXED, kernels.THRESHOLD]


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 30),
    counts=st.lists(st.integers(0, 20), min_size=2, max_size=2).filter(lambda c: sum(c) > 0),
    seed=st.integers(0, 2**32 - 1),
)
def test_compiled_urn_schedule_equals_the_numpy_loop(n, counts, seed):
    a = schedule_counts(n, counts, np.random.default_rng(seed))
    b = schedule_counts(n, counts, np.random.default_rng(seed), compiled=False)
    np.testing.assert_array_equal(a, b)
    assert a.dtype == b.dtype and a.shape == b.shape


@pytest.mark.parametrize("update", ["paper", "bayes"])
def test_paper_sized_crossover_is_the_same(update):
    model = paper_model()
    policy = threshold_policy(model, (-np.inf, 0.72), update)
    agnostic = ComplexityPolicy("trust-agnostic", TASK.complexities, [0.0, 1.0])
    kw = {"seed": 11, "belief_model": model}
    assert_same(
        crossover(model, TASK, [policy, agnostic], 40, **kw), crossover(model, TASK, [policy, agnostic], 40, compiled=False, **kw)
    )
