"""Property-based fuzzing of the HTTP API from its own OpenAPI schema (schemathesis, bounded in time).

Every operation, a few examples each, against a real uvicorn: no 500s, responses match the documented
schema, and every error body carries a message.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("uvicorn")
schemathesis = pytest.importorskip("schemathesis")

from hypothesis import HealthCheck, settings  # noqa: E402
from schemathesis.checks import not_a_server_error, response_schema_conformance  # noqa: E402

from flexopt.service.settings import Settings  # noqa: E402
from tests.test_service import _Server  # noqa: E402

# The committed schema (kept equal to the app's by test_service.test_openapi_committed_and_current).
schema = schemathesis.openapi.from_dict(
    json.loads((Path(__file__).resolve().parents[1] / "service" / "openapi.json").read_text()))


@pytest.fixture(scope="module")
def base_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    # Small limits keep the heavy endpoints cheap if a generated scene happens to be valid.
    with _Server(Settings(request_timeout=5.0, max_stroke_points=11, cache_size=0,
                          data_dir=tmp_path_factory.mktemp("data"))) as srv:
        yield srv.url


@schema.parametrize()
@settings(max_examples=12, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
def test_api_fuzz(case: schemathesis.Case, base_url: str) -> None:
    response = case.call(base_url=base_url, timeout=20)
    case.validate_response(response, checks=[not_a_server_error, response_schema_conformance])
    if response.status_code >= 400:
        body = response.json()
        assert isinstance(body.get("detail"), str) and body["detail"].strip(), body
