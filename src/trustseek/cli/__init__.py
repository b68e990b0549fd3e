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

# the modules that register the commands; the import order is the order of the help panels
# isort: off
from . import simulate  # simulate, reproduce
from . import fit  # fit, decode, select
from . import plan  # solve, agnostic, plot-q; preset, check
from . import interop  # export-pomdp, solve-pomdp-file
from . import serve  # serve, export
# isort: on

COMMAND_MODULES = (simulate, fit, plan, interop, serve)


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
