"""The server's log handler writes to the stderr of the moment: a command run in-process (as the
tests run ``trustseek serve``) must not leave later commands' logs on a closed stream."""

import io
import logging
import sys

from trustseek.cli.serve import CurrentStderr, log_to_stderr


def test_the_log_follows_the_current_stderr_and_is_added_once(monkeypatch):
    logger = logging.getLogger("trustseek")
    before = list(logger.handlers)
    try:
        first = io.StringIO()
        monkeypatch.setattr(sys, "stderr", first)
        log_to_stderr("info")
        log_to_stderr("info")
        first.close()  # as a test runner closes the stream it captured a command's output in
        second = io.StringIO()
        monkeypatch.setattr(sys, "stderr", second)
        logging.getLogger("trustseek.server").warning("after the first command")
        out = second.getvalue()
        assert "Logging error" not in out
        assert out.count("after the first command") == 1
        assert sum(isinstance(h, CurrentStderr) for h in logger.handlers) == 1
    finally:
        logger.handlers[:] = before
