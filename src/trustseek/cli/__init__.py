"""Command-line interface: a thin layer over the Python API.

Each module registers its commands on the shared Typer ``app``.  ``main`` turns
every :class:`~trustseek.errors.TrustseekError` into one clear line per problem
on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import sys

from rich.markup import escape

from ..errors import TrustseekError
from ._app import app, err_console

# the import order is the order of the help panels
# isort: off
from . import simulate  # noqa: F401  (simulate, reproduce)
from . import fit  # noqa: F401  (fit, decode, select)
from . import plan  # noqa: F401  (solve, agnostic, plot-q; preset, check)
from . import interop  # noqa: F401  (export-pomdp, solve-pomdp-file)
from . import serve  # noqa: F401  (serve, export)
# isort: on


def main() -> None:
    try:
        app(standalone_mode=True)
    except TrustseekError as exc:
        for line in exc.lines():
            err_console.print(f"[bold red]error:[/] {escape(line)}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except KeyboardInterrupt:
        err_console.print("interrupted")
        sys.exit(130)
