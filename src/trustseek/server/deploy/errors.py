"""What the decision API refuses, as domain errors: the HTTP layer (``http.STATUS``) alone says
which status each one is."""

from __future__ import annotations

from ...errors import TrustseekError


class DeployError(TrustseekError):
    """A request of a deploy session that is refused; ``message`` says why."""

    def __init__(self, message: str):
        self.message = message
        super().__init__([message])


class NoSession(DeployError):
    """No deploy session by that id."""


class NotAllowed(DeployError):
    """A well-formed request that the session does not allow (a complexity the task does not
    have, an observation the trial does not allow, a schedule request to another policy)."""


class Conflict(DeployError):
    """A request that the session's state does not allow now (not the next trial, a repeat
    that differs from what is stored)."""
