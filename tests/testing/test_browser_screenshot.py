"""The browser tests' screenshot (trustseek.testing.browser.screenshot): Chromium's transient
refusal of a capture is asked again once; every other failure is raised at once."""

from __future__ import annotations

import pytest
from playwright.sync_api import Error

from trustseek.testing.browser import screenshot

REFUSED = "Page.screenshot: Protocol error (Page.captureScreenshot): Unable to capture screenshot"


class Page:
    """A page whose first ``refusals`` captures fail with ``message``."""

    def __init__(self, refusals: int, message: str = REFUSED):
        self.refusals, self.message, self.calls = refusals, message, []

    def screenshot(self, **options):
        self.calls.append(options)
        if len(self.calls) <= self.refusals:
            raise Error(self.message)
        return b"png"


def test_a_refused_capture_is_taken_on_the_second_ask_with_the_same_options():
    page = Page(refusals=1)
    assert screenshot(page, path="x.png", full_page=True) == b"png"
    assert page.calls == [{"path": "x.png", "full_page": True}] * 2


def test_a_capture_refused_twice_fails():
    with pytest.raises(Error, match="Unable to capture screenshot"):
        screenshot(Page(refusals=2))


def test_another_error_is_not_retried():
    page = Page(refusals=1, message="Page.screenshot: Target page, context or browser has been closed")
    with pytest.raises(Error, match="has been closed"):
        screenshot(page)
    assert len(page.calls) == 1
