"""The flexopt HTTP service: ``create_app(settings=None)`` builds the FastAPI application.

The application: ``/health`` and ``/ready`` (here), the ``/v1`` routes (:mod:`.routes`, one module per
resource), the web page (:mod:`service.web`), the middleware (:mod:`.middleware`), problem-details errors
(:mod:`.errors`) and the OpenAPI document as committed in ``service/openapi.json``. The lifespan owns the
runtime state (:mod:`.runtime`): the worker pool, the computation slots, the response cache and the jobs.

Regenerate the committed schema with ``python -m flexopt.service.api.app > service/openapi.json``.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import Response
from fastapi_offline import FastAPIOffline
from starlette.exceptions import HTTPException

from .. import web
from ..schemas import METHODS, Health, Problem
from . import errors, routes
from .examples import add_examples
from .middleware import AllowedHosts, BodyLimit, FrameBlock, JsonOnly, RequestLog
from .runtime import Runtime, runtime
from .settings import Settings

__all__ = ["create_app", "openapi_json"]


def _package_version() -> str:
    try:
        return version("flexopt")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
        return "0+unknown"


def create_app(settings: Settings | None = None) -> FastAPI:
    """The FastAPI application (settings from the environment unless given)."""
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        from ...model.threads import limit_process

        limit_process()  # one BLAS thread in the server and the worker and job processes it starts (model.threads)
        rt = Runtime(settings)
        rt.start()
        app.state.runtime = rt
        try:
            yield
        finally:
            rt.stop()

    app = FastAPIOffline(
        title="flexopt",
        version=_package_version(),
        lifespan=lifespan,
        description="Large-stroke flexure hinges: templates, scenes, stroke-dependent natural "
        "frequencies and exact-constraint diagnosis. Errors are RFC 9457 problem "
        "details.",
    )
    # The runtime also exists before startup so that in-process tools (schema export) work without a lifespan.
    app.state.runtime = Runtime(settings)
    errors.install(app)

    @app.get("/health", response_model=Health, summary="Liveness (the process answers), version and methods")
    async def health() -> Health:
        return Health(version=_package_version(), methods=list(METHODS))

    @app.head("/health", summary="Liveness, without a body", operation_id="health_head")
    async def health_head() -> Response:
        return Response()

    _NOT_READY: dict[int | str, dict[str, Any]] = {
        503: {"model": Problem, "description": "not ready; detail says what is missing"}
    }

    @app.get(
        "/ready",
        response_model=Health,
        responses=_NOT_READY,
        summary="Readiness: the job store answers, the job dispatcher runs, the worker pool is up",
    )
    async def ready(request: Request) -> Health:
        why = await asyncio.to_thread(runtime(request).not_ready)
        if why:
            raise HTTPException(503, "not ready: " + "; ".join(why), headers={"Retry-After": "5"})
        return Health(version=_package_version(), methods=list(METHODS))

    @app.head("/ready", summary="Readiness, without a body", operation_id="ready_head", responses=_NOT_READY)
    async def ready_head(request: Request) -> Response:
        await ready(request)
        return Response()

    app.include_router(routes.router(settings))
    web.install(app)  # the page at / and its static assets
    app.add_middleware(JsonOnly)  # inside BodyLimit: a body too large is 413 whatever its type
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes, timeout=settings.body_timeout)
    app.add_middleware(AllowedHosts, hosts=settings.hosts())  # before anything reads the body (DNS rebinding)
    app.add_middleware(FrameBlock)  # every answer, a 400 for a foreign Host included
    app.add_middleware(RequestLog)  # added last: the outermost layer, sees every request and exception
    app.openapi = lambda: _openapi(app)  # type: ignore[method-assign]
    return app


def _openapi(app: FastAPI) -> dict[str, Any]:
    """FastAPI's document, corrected to describe what the service really does (built once, then cached):
    error bodies are ``application/problem+json`` (RFC 9457) and every 422 is a :class:`Problem`; bodies that
    are not JSON get 415 and bodies that are not UTF-8 or not JSON get 400 (or 422); the API key is optional
    (only servers with keys configured ask for it); the ``scene`` of a request is the full scene schema, so
    that a client or a fuzzer can build valid scenes from the document alone."""
    if app.openapi_schema:
        return app.openapi_schema
    from fastapi.openapi.utils import get_openapi

    from ...model.scene import Scene

    doc = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes)
    comps = doc.setdefault("components", {}).setdefault("schemas", {})
    scene = Scene.model_json_schema(ref_template="#/components/schemas/{model}")
    for name, sub in scene.pop("$defs", {}).items():
        if name in comps:  # pragma: no cover - a name clash would silently change another schema
            raise RuntimeError(f"scene schema part '{name}' clashes with an API schema")
        comps[name] = sub
    comps["Scene"] = scene
    for req in ("FrequencyCurveRequest", "DiagnosisRequest", "ModesRequest"):
        props = comps.get(req, {}).get("properties", {})
        if "scene" in props:
            props["scene"] = {
                "$ref": "#/components/schemas/Scene",
                "description": props["scene"].get("description", ""),
            }
    comps.pop("HTTPValidationError", None)
    comps.pop("ValidationError", None)
    # two models are called Problem (the error body and optim's problem): pydantic names them Problem-Input
    # and Problem-Output, or by their module paths (flexopt__service__schemas__Problem) once both are used
    # in one direction, by accident of use; give each its own name
    renames = {}
    for name in [k for k in comps if k.split("-")[0].split("__")[-1] == "Problem"]:
        is_error = {"detail", "errors", "status"} <= set(comps[name].get("properties", {}))
        renames[name] = "ProblemDetails" if is_error else "OptimisationProblem"
    text = json.dumps(doc)
    for old, new in renames.items():
        text = text.replace(f'"#/components/schemas/{old}"', f'"#/components/schemas/{new}"')
    doc = json.loads(text)
    comps = doc["components"]["schemas"]
    for old, new in renames.items():
        comps[new] = comps.pop(old)
    problem_ref = {"$ref": "#/components/schemas/ProblemDetails"}
    schemes = doc.get("components", {}).get("securitySchemes", {})
    for path_item in doc.get("paths", {}).values():
        for method, op in path_item.items():
            responses = op.setdefault("responses", {})
            if method in ("post", "put", "patch") and "requestBody" in op:
                responses.setdefault("400", {"description": "the body is not UTF-8 or not JSON"})
                responses.setdefault("415", {"description": "the body's Content-Type is not JSON"})
            for code, resp in responses.items():
                if code.isdigit() and int(code) >= 400:
                    resp["content"] = {"application/problem+json": {"schema": problem_ref}}
            if op.get("security") and schemes:  # keys are optional: no key is fine on a server without keys
                op["security"] = [*op["security"], {}]
    submit = doc["paths"].get("/v1/optimisations", {}).get("post")
    if submit is not None:  # the job id of a submission feeds the job's own operations (OpenAPI links)
        by_id = {op["operationId"]: op for op in doc["paths"].get("/v1/optimisations/{job_id}", {}).values()}
        submit["responses"]["202"]["links"] = {
            op_id.split("_v1_")[0]: {"operationId": op_id, "parameters": {"job_id": "$response.body#/id"}}
            for op_id in sorted(by_id)
        }
    add_examples(doc)
    app.openapi_schema = doc
    return doc


def openapi_json() -> str:
    """The OpenAPI document as committed in service/openapi.json (default settings)."""
    return json.dumps(create_app(Settings(api_keys="")).openapi(), indent=2, sort_keys=True) + "\n"


if __name__ == "__main__":  # pragma: no cover
    print(openapi_json(), end="")
