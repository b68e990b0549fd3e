"""One exception family: every public error type of the library is a ``TrustseekError``, so
that the CLI reports it as clean lines and callers can catch all of them at once."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import trustseek
from trustseek import paper_model, paper_task
from trustseek.errors import TrustseekError
from trustseek.model.jsonfile import ModelError, UnknownComplexityError
from trustseek.server.sessions import SessionError

# modules that only make sense as a program or inside Alembic
NOT_IMPORTED = ("trustseek.__main__", "trustseek.server.migrations")


def public_error_types() -> list[type[BaseException]]:
    found = []
    for info in pkgutil.walk_packages(trustseek.__path__, "trustseek."):
        if info.name.startswith(NOT_IMPORTED):
            continue
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if (
                inspect.isclass(obj)
                and issubclass(obj, BaseException)
                and obj.__module__ == module.__name__
                and not name.startswith("_")
            ):
                found.append(obj)
    return sorted(found, key=lambda t: f"{t.__module__}.{t.__qualname__}")


def _param(error_type: type[BaseException]):
    return pytest.param(error_type, id=f"{error_type.__module__}.{error_type.__qualname__}")


@pytest.mark.parametrize("error_type", [_param(t) for t in public_error_types()])
def test_every_public_error_type_is_a_trustseek_error(error_type):
    assert issubclass(error_type, TrustseekError)


def test_an_error_is_its_problem_lines():
    err = TrustseekError(["first", "second"], source="model.json")
    assert err.lines() == ["model.json: first", "model.json: second"]
    assert str(err) == "model.json: first\nmodel.json: second"
    assert TrustseekError("one").problems == ["one"]


@pytest.mark.parametrize(
    "lookup", [lambda: paper_model().complexity_index("medium"), lambda: paper_task().complexity_index("medium")]
)
def test_an_unknown_complexity_is_a_model_error_and_a_key_error(lookup):
    with pytest.raises(UnknownComplexityError) as info:
        lookup()
    assert isinstance(info.value, ModelError) and isinstance(info.value, KeyError)
    assert str(info.value) == "unknown complexity 'medium'; expected one of ['low', 'high']"


def test_a_session_error_carries_its_http_status():
    err = SessionError(409, "trial 3 is not the current trial")
    assert isinstance(err, TrustseekError)
    assert (err.status, err.message, err.lines()) == (
        409,
        "trial 3 is not the current trial",
        ["trial 3 is not the current trial"],
    )
