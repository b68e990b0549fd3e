"""How trustseek is packaged: the version comes from the installed distribution's metadata."""

from __future__ import annotations

import importlib.metadata

import trustseek
from trustseek.version import __version__


def test_version_is_the_distribution_version():
    assert __version__ == importlib.metadata.version("trustseek")
    assert trustseek.__version__ == __version__


def test_health_endpoint_reports_the_version(tmp_path):
    from fastapi.testclient import TestClient

    from trustseek.server import create_app

    with TestClient(create_app(f"sqlite:///{tmp_path / 'study.sqlite'}", token="experimenter-token")) as client:
        assert client.get("/api/health").json() == {"status": "ok", "version": __version__}
