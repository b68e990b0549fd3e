"""The one exception family that the CLI turns into clean error lines (exit code 2)."""

from __future__ import annotations

from collections.abc import Iterable


class TrustseekError(Exception):
    """Base class of user-facing errors.  ``problems`` holds one line per problem, so that one
    error can report everything wrong with an input at once; ``source`` names the input (a file,
    a request) and prefixes every line."""

    def __init__(self, problems: str | Iterable[str], source: str | None = None):
        self.problems = [problems] if isinstance(problems, str) else list(problems)
        self.source = source
        super().__init__("\n".join(self.lines()))

    def lines(self) -> list[str]:
        """One line per problem, each prefixed with the source when there is one."""
        where = f"{self.source}: " if self.source else ""
        return [f"{where}{p}" for p in self.problems]

    def __str__(self) -> str:
        # the problem lines as they are, also for subclasses that add a built-in base such as
        # KeyError (whose own __str__ would quote the message)
        return "\n".join(self.lines())
