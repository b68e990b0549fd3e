"""The one exception family that the CLI turns into clean error lines (exit code 2)."""


class TrustseekError(Exception):
    """Base class of user-facing errors.  ``problems`` holds one line per problem."""

    def __init__(self, problems, source: str | None = None):
        if isinstance(problems, str):
            problems = [problems]
        self.problems = list(problems)
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__("\n".join(f"{where}{p}" for p in self.problems))

    def lines(self) -> list[str]:
        where = f"{self.source}: " if self.source else ""
        return [f"{where}{p}" for p in self.problems]
