"""``/v1/pareto-fronts``: Pareto fronts of worst-case parasitic frequency against drive stiffness (optim/pareto.py),
jobs of their own kind (an example spec, submit, status and result, list, cancel or remove)."""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter, Header, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import Response
from starlette.exceptions import HTTPException

# optim.pareto imports pydantic and numpy only at module level (no CasADi)
from ....optim.pareto import ParetoSpec, example_spec
from ...schemas import Job, JobPage, Problem
from ..errors import JOBS, log
from ..guards import check_problem
from ..runtime import job_store, submit_job
from .optimisations import SUBMIT

__all__ = ["router"]

_KIND = "pareto-front"


def _front_job(job: dict | None, job_id: str) -> Job:
    if job is None or job["kind"] != _KIND:
        raise HTTPException(404, f"no Pareto front '{job_id}'")
    return Job(**job)


def _check(spec: ParetoSpec) -> None:
    """The problem's checks at submission (optimisations' :func:`check_problem`), its fields under ``problem``."""
    try:
        check_problem(spec.problem)
    except RequestValidationError as exc:
        raise RequestValidationError(
            [{**e, "loc": ("body", "problem", *tuple(e["loc"])[1:])} for e in exc.errors()]
        ) from None


def router(prefix: str) -> APIRouter:
    """The Pareto-front routes (under ``prefix``, ``/v1``)."""
    r = APIRouter(prefix=prefix)

    @r.get(
        "/pareto-fronts/example",
        response_model=ParetoSpec,
        summary="A small Pareto-front spec (a cross-spring pivot's length and thickness), to edit and submit",
    )
    async def pareto_example() -> dict[str, Any]:
        return example_spec()

    @r.post(
        "/pareto-fronts",
        status_code=202,
        response_model=Job,
        summary="Submit a Pareto front (worst-case parasitic frequency against drive stiffness, by "
        "epsilon-constraint with exact gradients, optionally checked by NSGA-II) as a job",
        responses=SUBMIT,
    )
    async def submit_pareto_front(
        spec: ParetoSpec,
        request: Request,
        response: Response,
        idempotency_key: str | None = Header(default=None, max_length=200),
    ) -> Job:
        await asyncio.to_thread(_check, spec)  # fail now, not in the job
        return await submit_job(
            request, response, {**spec.model_dump(mode="json"), "kind": _KIND}, idempotency_key, "pareto-fronts"
        )

    @r.get(
        "/pareto-fronts/{job_id}",
        response_model=Job,
        responses={404: {"model": Problem}, **JOBS},
        summary="Status, progress {done, total} of the cases of the current phase, and the front once succeeded",
    )
    async def get_pareto_front(job_id: str, request: Request) -> Job:
        return _front_job(await asyncio.to_thread(job_store(request).get, job_id, request.state.owner), job_id)

    @r.get(
        "/pareto-fronts", response_model=JobPage, responses=JOBS, summary="Pareto fronts of this API key, newest first"
    )
    async def list_pareto_fronts(
        request: Request, offset: int = Query(0, ge=0, le=1_000_000_000), limit: int = Query(20, ge=1, le=100)
    ) -> JobPage:
        items, total = await asyncio.to_thread(job_store(request).page, offset, limit, request.state.owner, None, _KIND)
        return JobPage(items=[Job(**j) for j in items], total=total, offset=offset, limit=limit)

    @r.delete(
        "/pareto-fronts/{job_id}",
        response_model=Job,
        responses={404: {"model": Problem}, **JOBS},
        summary="Cancel an unfinished Pareto front (running: after the cases in progress), or remove a finished one",
    )
    async def cancel_pareto_front(job_id: str, request: Request) -> Job:
        _front_job(await asyncio.to_thread(job_store(request).get, job_id, request.state.owner), job_id)
        job = await asyncio.to_thread(job_store(request).delete, job_id, request.state.owner)
        if job is None:  # removed in between
            raise HTTPException(404, f"no Pareto front '{job_id}'")
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
