"""``/v1/optimisations``: optimisation jobs (submit, status and results, list, cancel or remove).

The work runs in job processes (:mod:`service.jobs`); a curve too costly for a request is a job of this
collection too (``kind: frequency-curve``).
"""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, Header, Query, Request
from fastapi.responses import Response
from starlette.exceptions import HTTPException

from ...schemas import Job, JobPage, OptimisationProblem, Problem
from ..errors import ERRORS, JOBS, log
from ..guards import check_problem
from ..runtime import job_store, submit_job

__all__ = ["router"]

#: the responses of a submission
SUBMIT = {**ERRORS, **JOBS, 429: {"model": Problem, "description": "too many unfinished jobs of this API key"}}


def router(prefix: str) -> APIRouter:
    """The optimisation-job routes (under ``prefix``, ``/v1``)."""
    r = APIRouter(prefix=prefix)

    @r.post(
        "/optimisations", status_code=202, response_model=Job, summary="Submit an optimisation job", responses=SUBMIT
    )
    async def submit_optimisation(
        spec: OptimisationProblem,
        request: Request,
        response: Response,
        idempotency_key: str | None = Header(default=None, max_length=200),
    ) -> Job:
        await asyncio.to_thread(check_problem, spec)  # fail now, not in the job
        return await submit_job(request, response, spec.model_dump(mode="json"), idempotency_key, "optimisations")

    @r.get(
        "/optimisations/{job_id}",
        response_model=Job,
        summary="Status, progress, partial and final results",
        responses={404: {"model": Problem}, **JOBS},
    )
    async def get_optimisation(job_id: str, request: Request) -> Job:
        job = await asyncio.to_thread(job_store(request).get, job_id, request.state.owner)
        if job is None:
            raise HTTPException(404, f"no optimisation job '{job_id}'")
        return Job(**job)

    @r.get(
        "/optimisations",
        response_model=JobPage,
        summary="Optimisation jobs of this API key, newest first",
        responses=JOBS,
    )
    async def list_optimisations(
        request: Request, offset: int = Query(0, ge=0, le=1_000_000_000), limit: int = Query(20, ge=1, le=100)
    ) -> JobPage:
        items, total = await asyncio.to_thread(job_store(request).page, offset, limit, request.state.owner)
        return JobPage(items=[Job(**j) for j in items], total=total, offset=offset, limit=limit)

    @r.delete(
        "/optimisations/{job_id}",
        response_model=Job,
        summary="Cancel an unfinished job (queued: at once; running: after the cases in progress), or "
        "remove a finished one and its files",
        responses={404: {"model": Problem}, **JOBS},
    )
    async def cancel_optimisation(job_id: str, request: Request) -> Job:
        job = await asyncio.to_thread(job_store(request).delete, job_id, request.state.owner)
        if job is None:
            raise HTTPException(404, f"no optimisation job '{job_id}'")
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
