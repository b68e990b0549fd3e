"""Experiment 1 of a replicate encoded from the simulation's arrays equals the encoding of its trial log."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek.design.replicate import agnostic_of, experiment1_sequences
from trustseek.errors import TrustseekError
from trustseek.estimation.sequences import encode
from trustseek.estimation.trust_iohmm import preset_spec
from trustseek.model.presets import paper_model, paper_task
from trustseek.policies import randomized
from trustseek.simulation import simulate
from trustseek.solvers.agnostic import trust_agnostic_from_data
from trustseek.vocab import TRIAL_COLUMNS


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 12),
    low=st.integers(0, 15),
    high=st.integers(0, 15),
    ask=st.tuples(st.sampled_from([0.0, 0.2, 1.0]), st.sampled_from([0.0, 0.5, 1.0])),
    seed=st.integers(0, 2**32 - 1),
)
def test_sequences_from_arrays_equal_encode_of_the_trials(n, low, high, ask, seed):
    if low + high == 0:
        high = 1
    task = paper_task()
    sim = simulate(paper_model(), task, randomized({"low": ask[0], "high": ask[1]}), n, counts=(low, high), seed=seed)
    frame = sim.trials()[list(TRIAL_COLUMNS)]
    spec = preset_spec("paper", frame)
    expected = encode(frame, spec)
    seqs, got_spec = experiment1_sequences(sim)
    assert got_spec == spec
    for f in dataclasses.fields(expected):
        a, b = getattr(seqs, f.name), getattr(expected, f.name)
        if isinstance(b, np.ndarray):
            assert a.dtype == b.dtype and a.flags.c_contiguous == b.flags.c_contiguous, f.name
            np.testing.assert_array_equal(a, b, err_msg=f.name)
        else:
            assert a == b, f.name
    try:
        want = trust_agnostic_from_data(frame, task)
    except TrustseekError as exc:
        with pytest.raises(TrustseekError) as got:
            agnostic_of(sim)
        assert got.value.lines() == exc.lines()
    else:
        got_policy = agnostic_of(sim)
        np.testing.assert_array_equal(got_policy.p_ask, want.p_ask)
        assert got_policy.info == want.info


def test_unrecorded_simulation_is_refused():
    sim = simulate(paper_model(), paper_task(), randomized(), 2, counts=(3, 3), record=False)
    with pytest.raises(TrustseekError):
        experiment1_sequences(sim)
