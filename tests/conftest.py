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
