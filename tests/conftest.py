import os
from pathlib import Path

import numpy as np
import pytest

from trustseek import AssistancePOMDP, paper_model, paper_task


@pytest.fixture
def model():
    return paper_model()


@pytest.fixture
def task():
    return paper_task()


@pytest.fixture
def pomdp(model, task):
    return AssistancePOMDP(model, task)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


_ROOT = Path(__file__).resolve().parents[1]


def _root_entries() -> set[str]:
    return {n for n in os.listdir(_ROOT) if not n.startswith(".") and n != "__pycache__"}


@pytest.fixture(autouse=True)
def _nothing_written_into_the_checkout():
    """A test writes into its tmp_path, never into the checkout (a command's default output, such as
    decode's posteriors.csv, once landed at the root and was committed)."""
    before = _root_entries()
    yield
    new = _root_entries() - before
    assert not new, f"the test wrote {sorted(new)} into {_ROOT}: give the command an output under tmp_path"
