"""schemathesis against the ASGI app: every operation, examples from its OpenAPI description,
authenticated as the experimenter or with a real session's token; no 5xx and every response
matches the described status codes, content types and schemas."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from server_checks import api_ids, case_headers
from trustseek.server.app import create_app

TOKEN = "schema-test-token"
CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
]

_dir = tempfile.TemporaryDirectory(prefix="trustseek-schema-")
APP = create_app(f"sqlite:///{Path(_dir.name) / 'schema.sqlite'}", token=TOKEN)
schema = schemathesis.openapi.from_asgi("/openapi.json", APP)


@pytest.fixture(scope="module")
def ids() -> dict[str, str]:
    return make_ids()


def make_ids() -> dict[str, str]:
    """A study with a participant session, and a deploy session: real ids and their tokens."""
    return api_ids(TestClient(APP), TOKEN)


@schema.parametrize()
@settings(max_examples=20, deadline=None, suppress_health_check=list(HealthCheck), database=None)
def test_api_conforms(case, ids):
    case.call_and_validate(headers=case_headers(case, ids, TOKEN), checks=CHECKS)


def test_export_documents_its_file_types(ids):
    """The export answers CSV or Parquet, and its description says so (it said JSON)."""
    content = APP.openapi()["paths"]["/api/studies/{study_id}/export"]["get"]["responses"]["200"]["content"]
    assert set(content) == {"text/csv", "application/vnd.apache.parquet"}
    c = TestClient(APP)
    h = {"Authorization": f"Bearer {TOKEN}"}
    for fmt, media in (("csv", "text/csv"), ("parquet", "application/vnd.apache.parquet")):
        r = c.get(f"/api/studies/{ids['study']}/export", params={"format": fmt}, headers=h)
        assert r.status_code == 200 and r.headers["content-type"].split(";")[0] == media


@pytest.mark.parametrize("body", [b"\xff", b'{"agree": true, "x": "\xe9"}', b"\xfe\xff\xd8"])
def test_undecodable_json_body_is_a_422(body):
    """A JSON body that is not text was a 400 "error parsing the body", a status the routes do
    not document (400 means a well-formed request that is not allowed): now a 422 like any
    malformed body, on the participant's and the experimenter's routes alike."""
    ids = make_ids()  # sessions of its own: the generated examples may have ended the shared ones
    c = TestClient(APP)
    for path, token in (
        (f"/api/sessions/{ids['participant']}/consent", ids["participant_token"]),
        ("/api/studies", TOKEN),
        (f"/api/deploy/sessions/{ids['deploy']}/decide", ids["deploy_token"]),
    ):
        r = c.post(path, content=body, headers={"Authorization": f"Bearer {token}", "Content-Type": "application/json"})
        assert r.status_code == 422, (path, r.status_code, r.text)
        assert r.json()["detail"][0]["loc"] == ["body"]
    # valid JSON text still reaches the route
    r = c.post(
        f"/api/sessions/{ids['participant']}/events",
        content='{"events": [{"t": 1, "type": "caf\u00e9"}]}'.encode(),
        headers={"Authorization": f"Bearer {ids['participant_token']}", "Content-Type": "application/json"},
    )
    assert r.status_code == 200, r.text
