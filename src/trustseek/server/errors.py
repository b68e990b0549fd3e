"""What the server refuses, as domain errors: the session layers (``sessions``, ``lifecycle``,
``deploy.service``) raise them and know nothing of HTTP; the HTTP layer alone gives each its
status code (``middleware.STATUS``, the one mapping, used by the routes and ``deploy.http``)."""

from __future__ import annotations

from ..errors import TrustseekError


class Refused(TrustseekError):
    """A request that is refused; ``message`` says why."""

    def __init__(self, message: str):
        self.message = message
        super().__init__([message])


class NotAllowed(Refused):
    """A well-formed request that is not allowed (an action the trial does not allow, a
    complexity the task does not have, a status a study cannot take)."""


class NotFound(Refused):
    """No such session, study or questionnaire."""


class Conflict(Refused):
    """A request that the session's state does not allow now (not the current trial, a repeat
    that differs from what is stored, a session that has ended, the wrong kind of session)."""


class Gone(Refused):
    """A session whose link the experimenter has revoked."""


class TooLarge(Refused):
    """More events than a session or one of its trials may hold (a request body over the size
    limit is refused before it is read: ``middleware.read_body``)."""
