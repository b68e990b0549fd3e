"""One exception family: every public error type of the library is a ``TrustseekError``, so
that the CLI reports it as clean lines and callers can catch all of them at once."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import pytest

import trustseek
from trustseek import paper_model, paper_task
from trustseek.errors import TrustseekError
from trustseek.model.jsonfile import ModelError, UnknownComplexityError
from trustseek.server.errors import Conflict, Gone, NotAllowed, NotFound, TooLarge
from trustseek.server.middleware import status_of

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


def test_refusals_are_domain_errors_given_their_status_in_one_place():
    err = Conflict("trial 3 is not the current trial")
    assert isinstance(err, TrustseekError) and not hasattr(err, "status")
    assert (err.message, err.lines()) == ("trial 3 is not the current trial", ["trial 3 is not the current trial"])
    statuses = {kind: status_of(kind("x")) for kind in (NotAllowed, NotFound, Conflict, Gone, TooLarge)}
    assert statuses == {NotAllowed: 400, NotFound: 404, Conflict: 409, Gone: 410, TooLarge: 413}


#: the server's layers below HTTP: they raise domain errors and name no status code
SESSION_LAYERS = (
    "sessions",
    "answers",
    "lifecycle",
    "plan",
    "preview",
    "studies",
    "deploy/service",
    "deploy/store",
)


@pytest.mark.parametrize("name", SESSION_LAYERS)
def test_the_session_layers_name_no_http_status(name):
    source = (Path(trustseek.__file__).parent / "server" / f"{name}.py").read_text()
    assert "fastapi" not in source and "HTTPException" not in source
    assert not re.findall(r"\(\s*[45]\d\d\s*,", source), f"server/{name}.py passes a status code"
