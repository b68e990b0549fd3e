"""Debian's Chromium for the browser tests and the report screenshots: where it is, and the
flags that keep a headless run on this machine (no downloads, no background traffic), and a
screenshot that survives Chromium's transient refusal of a capture."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = (
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
)


def launch_chromium(playwright: Any, extra_args: tuple[str, ...] = ()) -> Any:
    """A headless Chromium through Playwright, from :data:`CHROMIUM` (never a downloaded build),
    with :data:`CHROMIUM_ARGS` and ``extra_args`` (e.g. ``--disable-webgl``)."""
    if not Path(CHROMIUM).exists():
        raise FileNotFoundError(f"{CHROMIUM} is missing: scripts/setup.sh installs Debian's chromium")
    args = [*CHROMIUM_ARGS, *extra_args]
    return playwright.chromium.launch(executable_path=CHROMIUM, args=args, headless=True)


def screenshot(page: Any, **options: Any) -> bytes:
    """``page.screenshot(**options)`` (of a page or a locator), asked once more a quarter of a second
    later when Chromium refuses the capture ("Unable to capture screenshot": a transient refusal on
    a busy machine, the same call taking the picture a moment later); any other error is raised."""
    from playwright.sync_api import Error

    try:
        return page.screenshot(**options)
    except Error as exc:
        if "Unable to capture screenshot" not in str(exc):
            raise
    time.sleep(0.25)
    return page.screenshot(**options)
