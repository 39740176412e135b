"""``/v1/topology-searches``: topology searches, jobs of their own kind (an example spec, submit, status and
result, list, cancel or remove)."""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter, Header, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import Response
from starlette.exceptions import HTTPException

from ....optim.topology.spec import TopologySpec, example_spec  # pydantic only (no CasADi)
from ...schemas import Job, JobPage, Problem
from ..errors import JOBS, log
from ..guards import nonfinite
from ..runtime import job_store, submit_job
from .optimisations import SUBMIT

__all__ = ["router"]

_TOPO = "topology-search"


def _topology_job(job: dict | None, job_id: str) -> Job:
    if job is None or job["kind"] != _TOPO:
        raise HTTPException(404, f"no topology search '{job_id}'")
    return Job(**job)


def router(prefix: str) -> APIRouter:
    """The topology-search routes (under ``prefix``, ``/v1``)."""
    r = APIRouter(prefix=prefix)

    @r.get(
        "/topology-searches/example",
        response_model=TopologySpec,
        summary="The default topology-search spec (TopologySpec defaults), to edit and submit",
    )
    async def topology_example() -> dict[str, Any]:
        return example_spec()

    @r.post(
        "/topology-searches",
        status_code=202,
        response_model=Job,
        summary="Submit a topology search: generate, screen, optimise and rank hinge topologies as a job",
        responses=SUBMIT,
    )
    async def submit_topology_search(
        spec: TopologySpec,
        request: Request,
        response: Response,
        idempotency_key: str | None = Header(default=None, max_length=200),
    ) -> Job:
        body = spec.model_dump(mode="json")
        where = nonfinite(spec.model_dump())  # the rest (bounds, descriptors) was checked by TopologySpec itself
        if where is not None:
            raise RequestValidationError(
                [
                    {
                        "loc": ("body", *where),
                        "type": "value_error",
                        "msg": "must be a finite number (Infinity and NaN are not accepted)",
                    }
                ]
            )
        return await submit_job(request, response, {**body, "kind": _TOPO}, idempotency_key, "topology-searches")

    @r.get(
        "/topology-searches/{job_id}",
        response_model=Job,
        responses={404: {"model": Problem}, **JOBS},
        summary="Status, progress {done, total} of the optimised cases, and the result once succeeded",
    )
    async def get_topology_search(job_id: str, request: Request) -> Job:
        return _topology_job(await asyncio.to_thread(job_store(request).get, job_id, request.state.owner), job_id)

    @r.get(
        "/topology-searches",
        response_model=JobPage,
        responses=JOBS,
        summary="Topology searches of this API key, newest first",
    )
    async def list_topology_searches(
        request: Request, offset: int = Query(0, ge=0, le=1_000_000_000), limit: int = Query(20, ge=1, le=100)
    ) -> JobPage:
        items, total = await asyncio.to_thread(job_store(request).page, offset, limit, request.state.owner, None, _TOPO)
        return JobPage(items=[Job(**j) for j in items], total=total, offset=offset, limit=limit)

    @r.delete(
        "/topology-searches/{job_id}",
        response_model=Job,
        responses={404: {"model": Problem}, **JOBS},
        summary="Cancel an unfinished topology search (running: after the cases in progress), or remove a finished one",
    )
    async def cancel_topology_search(job_id: str, request: Request) -> Job:
        _topology_job(await asyncio.to_thread(job_store(request).get, job_id, request.state.owner), job_id)
        job = await asyncio.to_thread(job_store(request).delete, job_id, request.state.owner)
        if job is None:  # removed in between
            raise HTTPException(404, f"no topology search '{job_id}'")
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

    return r
