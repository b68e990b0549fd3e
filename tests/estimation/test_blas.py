"""The compiled run's BLAS and LAPACK routines, found in scipy's OpenBLAS library without
importing scipy.linalg, are the ones scipy.linalg's own exported functions call: a fit through
either gives the same numbers bit for bit."""

from __future__ import annotations

import pytest

from trustseek.data import example_path, read_trials
from trustseek.estimation import FitOptions, blas, compiled_em, fit_trust_model


def test_the_library_s_routines_give_the_numbers_of_scipy_linalg_s():
    assert blas.library() is not None  # scipy's wheel, as setup.sh installs it: the direct path is taken
    frame = read_trials(example_path())
    options = FitOptions(restarts=4, seed=3, n_jobs=1)
    direct = fit_trust_model(frame, options=options)
    try:
        compiled_em.bind(blas.routines(direct=False))
        through_scipy = fit_trust_model(frame, options=options)
    finally:
        compiled_em.bind(blas.routines())
    assert direct.loglik == through_scipy.loglik
    assert direct.model.to_dict() == through_scipy.model.to_dict()
    assert [r.iterations for r in direct.runs] == [r.iterations for r in through_scipy.runs]


def test_a_routine_without_an_address_is_refused():
    with pytest.raises(ValueError, match="without an address"):
        compiled_em.bind((1, 0, 1))
