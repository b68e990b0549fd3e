"""The free cells as stick-breaking fractions (:mod:`trustseek.estimation.sticks`): the compiled
maps give the numpy formulas' values and gradient, for the pooled structure and a mixture's tables."""

import numpy as np
import pytest

from trustseek.estimation import encode, paper_spec
from trustseek.estimation.estep import Workspace
from trustseek.estimation.mixture_em import MixtureStructure, MixtureWorkspace
from trustseek.estimation.sticks import Sticks
from trustseek.estimation.structure import Structure
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design


def sticks_reference(sticks, theta, base, st):
    """The stick-breaking values and gradient by the numpy formulas, part by part."""
    arrays = {"initial": base.initial.copy(), "emission": base.emission.copy(), "transition": base.transition.copy()}
    grad = np.empty_like(theta)
    pos = 0
    for part in sticks.parts:
        R, m = part.rows, part.m
        v = theta[pos : pos + R * (m - 1)].reshape(m - 1, R)
        rem = part.mass.copy()
        vals = np.empty((R, m))
        for j in range(m - 1):
            vals[:, j] = rem * v[j]
            rem = rem * (1 - v[j])
        vals[:, m - 1] = rem
        arrays[part.table].ravel()[part.dst] = vals.ravel()[part.src]
        counts = getattr(st, part.table).ravel()[part.dst]
        w = np.bincount(part.src, weights=counts, minlength=R * m).reshape(R, m) + sticks.structure.spec.prior
        tail = np.cumsum(w[:, ::-1], axis=1)[:, ::-1]
        grad[pos : pos + R * (m - 1)] = (w[:, : m - 1].T / v - tail[:, 1:].T / (1 - v)).ravel()
        pos += R * (m - 1)
    return arrays, grad


@pytest.mark.parametrize("types", [0, 2])
def test_compiled_sticks_equal_the_numpy_formulas(types):
    spec = paper_spec()
    seqs = encode(simulate_design(paper_model(), 12, seed=5), spec)
    if types:
        s = MixtureStructure(spec, seqs, types)
        sticks, work = s.sticks(), MixtureWorkspace(seqs, s)
    else:
        s = Structure(spec, seqs)
        sticks, work = Sticks(s), Workspace(seqs, *s.dims)
    rng = np.random.default_rng(types)
    base = s.random(rng)
    for _ in range(3):
        theta = rng.uniform(0.01, 0.99, sticks.size)
        p = sticks.params(theta, base)
        st = work.estep(p)
        arrays, grad = sticks_reference(sticks, theta, base, st)
        for name, a in arrays.items():
            assert np.array_equal(getattr(p, name), a)
        assert np.array_equal(sticks.gradient(theta, st), grad)
        assert np.allclose(sticks.theta(p), theta)
