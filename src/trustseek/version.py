"""The installed distribution's version, read once from its package metadata.

A module of its own at the bottom of the layers, so that any module (the report, the
server's health endpoint) can name the version without importing the package root.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__: str = version("trustseek")
except PackageNotFoundError:  # a source tree on sys.path that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
