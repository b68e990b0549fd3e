"""The experiment server: studies with a live policy, participant sessions in the browser, a live
dashboard, export to the canonical trial log, and a decision API for robots
(``create_app("sqlite:///study.sqlite", token="secret")``; docs/architecture.md lists the modules).
"""

from .app import create_app

__all__ = ["create_app"]
