"""A seed given as a numpy SeedSequence: the same object gives the same numbers however often it
is passed (a fit or a simulation drew its children from it, so the second call with the same
options drew others: another fit, another log-likelihood)."""

import numpy as np
import pandas as pd

from trustseek.estimation import encode, fit_iohmm, paper_spec
from trustseek.estimation.options import FitOptions
from trustseek.model.presets import paper_model, paper_task
from trustseek.policies import randomized
from trustseek.seeds import seed_sequence
from trustseek.simulation import simulate
from trustseek.simulation.designs import simulate_design


def test_a_seed_sequence_is_copied_as_it_stands_and_never_moved():
    given = np.random.SeedSequence(7)
    given.spawn(3)  # children drawn before: the copy goes on after them
    own = seed_sequence(given)
    assert own is not given
    assert [c.spawn_key for c in own.spawn(2)] == [(3,), (4,)]
    assert given.n_children_spawned == 3
    assert seed_sequence(5).entropy == 5


def test_the_same_fit_options_give_the_same_fit_twice():
    seqs = encode(simulate_design(paper_model(), 9, seed=0), paper_spec())
    given = np.random.SeedSequence(1)
    options = FitOptions(restarts=3, seed=given, n_jobs=1)
    a, b = (fit_iohmm(seqs, paper_spec(), options) for _ in range(2))
    assert [r.history for r in a.runs] == [r.history for r in b.runs]
    assert a.loglik == b.loglik
    assert given.n_children_spawned == 0
    by_number = fit_iohmm(seqs, paper_spec(), FitOptions(restarts=3, seed=1, n_jobs=1))
    assert by_number.loglik == a.loglik  # the same as the seed's number


def test_the_same_seed_sequence_simulates_the_same_trials_twice():
    given = np.random.SeedSequence(3)
    policy = randomized({"low": 0.1, "high": 0.4})
    a, b = (simulate(paper_model(), paper_task(), policy, 5, counts=(17, 17), seed=given).trials() for _ in range(2))
    pd.testing.assert_frame_equal(a, b)
    assert given.n_children_spawned == 0
