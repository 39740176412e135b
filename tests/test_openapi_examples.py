"""Every example in the OpenAPI document is a request the service accepts (issue 26, item 7).

Without examples Swagger UI's "Try it out" built the body from the schema and its made-up scene was a 422.
Every operation with a JSON body must carry examples, and each is sent to a running app (path parameters
from their examples) and must be answered 2xx; the jobs it submits are cancelled at once.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

from flexopt.service.api.app import openapi_json  # noqa: E402
from flexopt.service.api.settings import Settings  # noqa: E402

from .test_service import _Server  # noqa: E402


def _examples() -> list[tuple[str, str, str, Any]]:
    """(method, path with parameters filled in, example name, body) of every example in the document."""
    return _scan()[0]


def _scan() -> tuple[list[tuple[str, str, str, Any]], list[str]]:
    """The examples, and the operations that lack one (a JSON body, or a path parameter, without example)."""
    import json

    out, missing = [], []
    for path, item in json.loads(openapi_json())["paths"].items():
        for method, op in item.items():
            content = op.get("requestBody", {}).get("content", {}).get("application/json")
            if content is None:
                continue
            filled = path
            for p in op.get("parameters", []):
                if p.get("in") == "path":
                    if "example" not in p:
                        missing.append(f"{method.upper()} {path}: path parameter '{p['name']}' has no example")
                    filled = filled.replace("{" + p["name"] + "}", str(p.get("example")))
            if not content.get("examples"):
                missing.append(
                    f"{method.upper()} {path}: a JSON body without examples (Swagger UI would make one "
                    "up from the schema)"
                )
                continue
            out += [(method, filled, name, ex["value"]) for name, ex in content["examples"].items()]
    return out, missing


def test_every_json_body_has_examples() -> None:
    examples, missing = _scan()
    assert not missing, "; ".join(missing)
    assert len(examples) >= 6


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    settings = Settings(
        data_dir=tmp_path_factory.mktemp("data"), executor="thread", max_jobs=1, job_workers=1, request_timeout=300
    )
    with _Server(settings) as server:
        yield server.url


@pytest.mark.slow
@pytest.mark.parametrize("method, path, name, body", _examples(), ids=lambda v: v if isinstance(v, str) else "")
def test_example_is_accepted(url: str, method: str, path: str, name: str, body: Any) -> None:
    r = httpx.request(method.upper(), f"{url}{path}", json=body, timeout=300)
    try:
        assert 200 <= r.status_code < 300, f"{method.upper()} {path} example '{name}': {r.status_code} {r.text}"
    finally:
        if r.status_code == 202 and "location" in r.headers:  # a job: cancel it, the example only has to start
            httpx.delete(f"{url}{r.headers['location']}")
