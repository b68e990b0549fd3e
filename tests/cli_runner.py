"""Running the command line in the test process, as a user would from a shell."""

from __future__ import annotations

import contextlib
import io
import sys
from unittest import mock


def run_cli(argv: list[str], stdout: bool = True) -> tuple[int, str]:
    """``trustseek *argv`` in this process: its exit code, and what it printed on stderr
    (with ``stdout``, stdout first, then stderr)."""
    from trustseek.cli import main

    out, err = io.StringIO(), io.StringIO()
    code: int | str | None = 0
    with mock.patch.object(sys, "argv", ["trustseek", *argv]), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main()
        except SystemExit as exc:
            code = exc.code
    return (code if isinstance(code, int) else 1), (out.getvalue() if stdout else "") + err.getvalue()
