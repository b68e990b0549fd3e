"""The study's ``scene`` option: the participant's page is told which scene the study asks for
(``3d`` by default, or ``2d``); any other value is refused with a located error."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from trustseek.server import create_app

TOKEN = "experimenter-secret"
H = {"Authorization": f"Bearer {TOKEN}"}
BLOCKS = [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}}]


@pytest.fixture
def client(tmp_path):
    with TestClient(create_app(f"sqlite:///{tmp_path / 'scene.sqlite'}", token=TOKEN)) as c:
        yield c


@pytest.mark.parametrize(("asked", "told"), [(None, "3d"), ("3d", "3d"), ("2d", "2d")])
def test_the_page_is_told_the_scene(client, asked, told):
    body = {"name": "s", "blocks": BLOCKS, **({"scene": asked} if asked else {})}
    r = client.post("/api/studies", json=body, headers=H)
    assert r.status_code == 201, r.text
    (info,) = client.post(f"/api/studies/{r.json()['id']}/sessions", json={"count": 1}, headers=H).json()
    state = client.get("/api/session", headers={"Authorization": f"Bearer {info['token']}"})
    assert state.status_code == 200, state.text
    assert state.json()["scene"] == told


def test_an_unknown_scene_is_refused(client):
    r = client.post("/api/studies", json={"name": "s", "blocks": BLOCKS, "scene": "4d"}, headers=H)
    assert r.status_code in (400, 422)
    assert "scene" in r.text and "2d" in r.text
