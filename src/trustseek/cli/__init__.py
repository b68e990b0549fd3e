"""Command-line interface: a thin layer over the Python API.

Each module registers its commands on the shared Typer ``app``; a command's module is imported
only when that command runs (:mod:`._lazy`), so ``--help`` starts at once.  ``main`` turns
every :class:`~trustseek.errors.TrustseekError` into one clear line per problem
on stderr and exit code 2, never a traceback; so is a command that needs an optional
extra (``server``, ``plots``) which is not installed.
"""

from __future__ import annotations

import sys

from rich.markup import escape

from ..errors import TrustseekError
from ._app import app, err_console

#: the optional extras of pyproject.toml, by the top-level module of each of their packages
EXTRAS = {
    "fastapi": "server",
    "uvicorn": "server",
    "sqlalchemy": "server",
    "alembic": "server",
    "httpx": "server",
    "psycopg": "server",
    "matplotlib": "plots",
    "jinja2": "plots",
    "dask": "design",
}


def missing_extra(exc: ModuleNotFoundError) -> TrustseekError | None:
    """The error to show when ``exc`` is a package of an optional extra that is not installed;
    None when it is not (then it is a bug, and its traceback is what to see)."""
    module = (exc.name or "").partition(".")[0]
    extra = EXTRAS.get(module)
    if extra is None:
        return None
    return TrustseekError(
        [f"this command needs the optional {extra!r} dependencies ({module} is not installed): pip install 'trustseek[{extra}]'"]
    )


def main() -> None:
    try:
        app(standalone_mode=True)
    except TrustseekError as exc:
        _exit_with(exc)
    except ModuleNotFoundError as exc:
        error = missing_extra(exc)
        if error is None:
            raise
        _exit_with(error)
    except KeyboardInterrupt:
        err_console.print("interrupted")
        sys.exit(130)


def _exit_with(error: TrustseekError) -> None:
    for line in error.lines():
        err_console.print(f"[bold red]error:[/] {escape(line)}", highlight=False, soft_wrap=True)
    sys.exit(2)
