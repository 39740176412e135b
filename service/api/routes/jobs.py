"""One factory for the job collections (``/optimisations``, ``/topology-searches``, ``/pareto-fronts``): submit,
status and result, list, cancel or remove, and an example spec, parameterised by the job's kind and its spec
model. Each collection module declares a :class:`JobKind` and calls :func:`job_router`."""

from __future__ import annotations

import asyncio
import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from fastapi import APIRouter, Header, Query, Request
from fastapi.responses import Response
from pydantic import BaseModel
from starlette.exceptions import HTTPException

from ...schemas import Job, JobPage, Problem
from ..cost import estimate_job
from ..errors import ERRORS, JOBS, log
from ..runtime import job_store, runtime, submit_job

__all__ = ["SUBMIT", "JobKind", "job_router"]

#: the responses of a submission
SUBMIT = {
    **ERRORS,
    **JOBS,
    413: {
        "model": Problem,
        "description": "request body too large, or the job's estimated cost over this server's "
        "max_batch_cost (the detail names the fields to reduce)",
    },
    429: {"model": Problem, "description": "too many unfinished jobs of this API key"},
}


@dataclass(frozen=True)
class JobKind:
    """A job collection: its URL, the ``kind`` stored with its jobs, its spec model and its words.

    A submission is checked, then its cost estimated (:mod:`..cost`): over ``max_batch_cost`` it is refused
    (413, one line with the estimate, the limit and the fields to reduce), else stored with its estimate.
    ``kind`` None (optimisations): the spec is stored as it is, and reads, lists and cancels see jobs of every
    kind (a curve run as a job is read under ``/optimisations``). ``check`` runs in a worker thread before a
    job is stored (422s naming the field). ``names`` and ``summaries`` are the routes' function names (their
    OpenAPI operation ids) and summaries, keyed ``example``, ``submit``, ``get``, ``list``, ``cancel``.
    """

    collection: str
    kind: str | None
    spec_model: type[BaseModel]
    missing: str  # the 404's words: "no <missing> '<id>'"
    names: dict[str, str]
    summaries: dict[str, str]
    check: Callable[[Any], None] | None = None
    example: Callable[[], dict[str, Any]] | None = None


def _typed(fn: Callable[..., Any], **annotations: Any) -> Callable[..., Any]:
    """``fn`` with the annotations of some parameters replaced (FastAPI reads the signature): the spec
    parameter gets the collection's model."""
    sig = inspect.signature(fn)
    fn.__signature__ = sig.replace(  # type: ignore[attr-defined]
        parameters=[p.replace(annotation=annotations.get(p.name, p.annotation)) for p in sig.parameters.values()]
    )
    return fn


def job_router(prefix: str, k: JobKind) -> APIRouter:
    """The routes of collection ``k`` under ``prefix`` (``/v1``)."""
    r = APIRouter(prefix=prefix)
    base = f"/{k.collection}"

    def found(job: dict | None, job_id: str) -> Job:
        if job is None or (k.kind is not None and job["kind"] != k.kind):
            raise HTTPException(404, f"no {k.missing} '{job_id}'")
        return Job(**job)

    if k.example is not None:
        example = k.example

        async def get_example() -> dict[str, Any]:
            return example()

        get_example.__name__ = k.names["example"]
        r.get(f"{base}/example", response_model=k.spec_model, summary=k.summaries["example"])(get_example)

    async def submit(
        spec: Any,
        request: Request,
        response: Response,
        idempotency_key: str | None = Header(default=None, max_length=200),
    ) -> Job:
        if k.check is not None:
            await asyncio.to_thread(k.check, spec)  # fail now, not in the job
        limit = runtime(request).settings.max_batch_cost
        est = await asyncio.to_thread(estimate_job, k.kind or "optimisation", spec)
        if est.seconds > limit:
            raise HTTPException(
                413,
                f"estimated cost {est.seconds:,.0f} s ({est.what}) exceeds this server's limit of {limit:,.0f} s "
                f"for a job; reduce {' or '.join(est.drivers[:2])}",
            )
        body = spec.model_dump(mode="json")
        if k.kind is not None:
            body = {**body, "kind": k.kind}
        return await submit_job(request, response, body, idempotency_key, k.collection, est.to_dict(limit))

    submit.__name__ = k.names["submit"]
    r.post(base, status_code=202, response_model=Job, summary=k.summaries["submit"], responses=SUBMIT)(
        _typed(submit, spec=k.spec_model)
    )

    async def get(job_id: str, request: Request) -> Job:
        return found(await asyncio.to_thread(job_store(request).get, job_id, request.state.owner), job_id)

    get.__name__ = k.names["get"]
    r.get(
        f"{base}/{{job_id}}",
        response_model=Job,
        summary=k.summaries["get"],
        responses={404: {"model": Problem}, **JOBS},
    )(get)

    async def page(
        request: Request, offset: int = Query(0, ge=0, le=1_000_000_000), limit: int = Query(20, ge=1, le=100)
    ) -> JobPage:
        items, total = await asyncio.to_thread(
            job_store(request).page, offset, limit, request.state.owner, None, k.kind
        )
        return JobPage(items=[Job(**j) for j in items], total=total, offset=offset, limit=limit)

    page.__name__ = k.names["list"]
    r.get(base, response_model=JobPage, summary=k.summaries["list"], responses=JOBS)(page)

    async def cancel(job_id: str, request: Request) -> Job:
        store = job_store(request)
        if k.kind is not None:
            found(await asyncio.to_thread(store.get, job_id, request.state.owner), job_id)
        job = await asyncio.to_thread(store.delete, job_id, request.state.owner)
        if job is None:  # no such job, or removed in between
            raise HTTPException(404, f"no {k.missing} '{job_id}'")
        log.info(
            "job deleted or cancelled",
            extra={
                "event": "job.delete",
                "job_id": job_id,
                "status": job["status"],
                "request_id": request.state.request_id,
            },
        )
        return Job(**job)

    cancel.__name__ = k.names["cancel"]
    r.delete(
        f"{base}/{{job_id}}",
        response_model=Job,
        summary=k.summaries["cancel"],
        responses={404: {"model": Problem}, **JOBS},
    )(cancel)
    return r
