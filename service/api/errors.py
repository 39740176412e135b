"""The one place where exceptions become HTTP responses (RFC 9457 problem-details bodies).

::

    model.FlexoptError      -> 422 (SceneError, ModelSizeError, EquilibriumError: the input cannot be analysed)
      KernelBuildError      -> 500 (a server-side compiler problem)
    jobs.worker.ComputationFailed -> 422 (the numbers of a valid scene broke the computation: the fields named)
    RequestValidationError  -> 422 with one entry per invalid field (loc path and reason)
    jobs.store.KeyReused    -> 422 at header Idempotency-Key
    jobs.store.TooManyJobs  -> 429 with Retry-After
    jobs.store.StoreUnavailable -> 503 with Retry-After (the job database is locked or unreachable)
    HTTPException           -> its status (404, 401, 413, ...)
    guards.TooCostly        -> 413 (a computation estimated past the server's cost limit)
    Busy                    -> 429 with Retry-After
    ComputeTimeout          -> 504
    anything else           -> 500 with a generic message (details only in the server log); the
                               connection stays open (middleware.RequestLog)

``ERRORS``, ``HEAVY`` and ``JOBS`` document these error responses on the routes (OpenAPI ``responses``).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping, Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from ..jobs.worker import ComputationFailed
from ..schemas import FieldError, Problem

__all__ = ["Busy", "ComputeTimeout", "ERRORS", "HEAVY", "JOBS", "problem", "install", "validation_errors"]

log = logging.getLogger("flexopt.service")

_TITLES = {
    400: "Bad request",
    401: "Unauthorized",
    404: "Not found",
    405: "Method not allowed",
    408: "Request timeout",
    413: "Payload too large",
    415: "Unsupported media type",
    422: "Unprocessable content",
    429: "Too many requests",
    500: "Internal server error",
    503: "Service unavailable",
    504: "Gateway timeout",
    406: "Not acceptable",
}


ERRORS: dict[int | str, dict[str, Any]] = {
    422: {"model": Problem, "description": "invalid input (field path and reason in errors)"},
    401: {"model": Problem, "description": "API key missing or invalid (when keys are configured)"},
    413: {"model": Problem, "description": "request body too large"},
}
#: the responses of a route that computes (in the worker pool, within the slot and time limits)
HEAVY: dict[int | str, dict[str, Any]] = {
    **ERRORS,
    429: {"model": Problem, "description": "too many concurrent computations; see Retry-After"},
    504: {"model": Problem, "description": "the computation exceeded the time limit"},
}
#: the responses of a route that reads or writes the job store
JOBS: dict[int | str, dict[str, Any]] = {
    503: {"model": Problem, "description": "the job store is unavailable; see Retry-After"}
}


class Busy(Exception):
    """Too many heavy computations are running; the client should retry after ``retry_after`` seconds."""

    def __init__(self, retry_after: int, limit: int) -> None:
        self.retry_after = retry_after
        super().__init__(
            f"the server is running its limit of {limit} concurrent computations; retry after {retry_after} s"
        )


class ComputeTimeout(Exception):
    """A synchronous computation exceeded the per-request time limit."""

    def __init__(self, limit: float) -> None:
        super().__init__(
            f"the computation exceeded the server's time limit of {limit:g} s; use fewer stroke "
            f"points, a cheaper method, or a smaller model"
        )


def problem(
    status: int, detail: str, errors: list[FieldError] | None = None, headers: dict[str, str] | None = None
) -> JSONResponse:
    """A problem-details response."""
    body = Problem(title=_TITLES.get(status, "Error"), status=status, detail=detail, errors=errors or [])
    return JSONResponse(
        body.model_dump(mode="json"), status_code=status, headers=headers, media_type="application/problem+json"
    )


def _loc(loc: Any) -> list[str | int]:
    return [p if isinstance(p, int) else str(p) for p in loc]


def validation_errors(errs: Sequence[Mapping[str, Any]], prefix: tuple[str | int, ...] = ()) -> list[FieldError]:
    """pydantic error dicts -> FieldError entries with readable messages."""
    out = []
    for e in errs:
        msg = str(e.get("msg", "invalid value")).removeprefix("Value error, ")
        if e.get("type") == "extra_forbidden":
            msg = "unknown field; remove it or check its spelling"
        elif e.get("type") == "missing":
            msg = "required field is missing; add it"
        out.append(FieldError(loc=_loc((*prefix, *e.get("loc", ()))), msg=msg))
    return out


def _field_path(field: str) -> list[str | int]:
    """``elements[2].nodes`` -> ``["elements", 2, "nodes"]`` (SceneError's dotted form as a loc path)."""
    out: list[str | int] = []
    for part in re.findall(r"[^.\[\]]+|\[\d*\]", field):
        if part.startswith("["):
            if part[1:-1]:
                out.append(int(part[1:-1]))
        else:
            out.append(part)
    return out


def _summary(errors: list[FieldError]) -> str:
    def path(loc: list[str | int]) -> str:
        return ".".join(f"[{p}]" if isinstance(p, int) else p for p in loc).replace(".[", "[")

    return "; ".join(f"{path(e.loc)}: {e.msg}" for e in errors[:10]) + (" ..." if len(errors) > 10 else "")


def install(app: FastAPI) -> None:
    """Register every exception handler on ``app``."""
    from ...model.errors import FlexoptError, KernelBuildError, SceneError
    from ..jobs.store import KeyReused, StoreUnavailable, TooManyJobs
    from .guards import TooCostly

    @app.exception_handler(RequestValidationError)
    async def _request_validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        errors = validation_errors(list(exc.errors()))
        return problem(422, _summary(errors) or "invalid request", errors)

    @app.exception_handler(ValidationError)
    async def _scene_validation(_: Request, exc: ValidationError) -> JSONResponse:
        # Scene.model_validate inside a route: the location is inside the request's "scene" field.
        errors = validation_errors(list(exc.errors()), ("body", "scene"))
        return problem(422, _summary(errors), errors)

    @app.exception_handler(KernelBuildError)
    async def _kernel(_: Request, exc: KernelBuildError) -> JSONResponse:
        log.error("kernel build failed: %s", exc)
        return problem(500, str(exc))

    @app.exception_handler(FlexoptError)
    async def _model(_: Request, exc: FlexoptError) -> JSONResponse:
        errors = []
        if isinstance(exc, SceneError):
            loc: list[str | int] = ["body", "scene", *_field_path(exc.field)] if exc.field else []
            errors = [FieldError(loc=loc, msg=exc.message)]
        return problem(422, str(exc), errors)

    @app.exception_handler(ComputationFailed)
    async def _computation(_: Request, exc: ComputationFailed) -> JSONResponse:
        locs = [["body", "scene", *_field_path(f)] for f in exc.fields] or [["body", "scene"]]
        return problem(422, str(exc), [FieldError(loc=loc, msg=str(exc)) for loc in locs])

    @app.exception_handler(KeyReused)
    async def _key_reused(_: Request, exc: KeyReused) -> JSONResponse:
        return problem(422, str(exc), [FieldError(loc=["header", "Idempotency-Key"], msg=str(exc))])

    @app.exception_handler(TooManyJobs)
    async def _too_many_jobs(_: Request, exc: TooManyJobs) -> JSONResponse:
        return problem(429, str(exc), headers={"Retry-After": "30"})

    @app.exception_handler(StoreUnavailable)
    async def _store(_: Request, exc: StoreUnavailable) -> JSONResponse:
        log.warning("job store unavailable: %s", exc)
        return problem(503, str(exc), headers={"Retry-After": "5"})

    @app.exception_handler(StarletteHTTPException)
    async def _http(_: Request, exc: StarletteHTTPException) -> JSONResponse:
        detail = str(exc.detail)
        if exc.status_code == 400 and detail == "There was an error parsing the body":  # FastAPI's wording
            detail = "the body could not be read: send JSON encoded as UTF-8"
        return problem(exc.status_code, detail, headers=getattr(exc, "headers", None))

    @app.exception_handler(TooCostly)
    async def _too_costly(_: Request, exc: TooCostly) -> JSONResponse:
        return problem(413, str(exc))

    @app.exception_handler(Busy)
    async def _busy(_: Request, exc: Busy) -> JSONResponse:
        return problem(429, str(exc), headers={"Retry-After": str(exc.retry_after)})

    @app.exception_handler(ComputeTimeout)
    async def _timeout(_: Request, exc: ComputeTimeout) -> JSONResponse:
        return problem(504, str(exc))

    @app.exception_handler(Exception)
    async def _unexpected(_: Request, exc: Exception) -> JSONResponse:
        log.exception("unhandled error", exc_info=exc)
        return problem(500, "internal error; the server log has the details")
