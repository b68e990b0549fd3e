"""Debian's Chromium for the browser tests and the report screenshots: where it is, and the
flags that keep a headless run on this machine (no downloads, no background traffic)."""

from __future__ import annotations

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
