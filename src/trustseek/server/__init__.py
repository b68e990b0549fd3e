"""The experiment server: studies with a live policy, participant sessions in the browser,
a live dashboard, export to the canonical trial log, and a decision API for robots.

    from trustseek.server import create_app
    app = create_app("sqlite:///study.sqlite", token="secret")

Modules: ``orm`` (schema), ``db`` (engine + Alembic migrations), ``studies`` (study
configuration), ``sessions`` (trial logic), ``routes`` (HTTP), ``export``, ``app``.
"""

from .app import create_app

__all__ = ["create_app"]
