"""The server's log goes to the stderr of the moment while the server runs, and leaves no handler
behind: a command run in-process (as the tests run ``trustseek serve``) must not put later
commands' logs on a closed stream, nor into their output."""

import io
import logging
import sys

from trustseek.cli.serve import log_to_stderr


def test_the_log_follows_the_current_stderr_while_serving_and_is_removed_after(monkeypatch):
    logger = logging.getLogger("trustseek")
    before = list(logger.handlers)
    first = io.StringIO()
    monkeypatch.setattr(sys, "stderr", first)
    with log_to_stderr("info"):
        first.close()  # as a test runner closes the stream it captured a command's output in
        second = io.StringIO()
        monkeypatch.setattr(sys, "stderr", second)
        logging.getLogger("trustseek.server").info("while serving")
    logging.getLogger("trustseek.estimation").info("a later command")
    out = second.getvalue()
    assert "Logging error" not in out
    assert out.count("while serving") == 1 and "a later command" not in out
    assert logger.handlers == before
