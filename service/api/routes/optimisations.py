"""``/v1/optimisations``: optimisation jobs (submit, status and results, list, cancel or remove).

The work runs in job processes (:mod:`service.jobs`); a curve too costly for a request is a job of this
collection too (``kind: frequency-curve``), and every job of the API key is read, listed and cancelled here.
"""

from __future__ import annotations

from fastapi import APIRouter

from ...schemas import OptimisationProblem
from ..guards import check_problem
from .jobs import SUBMIT, JobKind, job_router

__all__ = ["KIND", "SUBMIT", "router"]

KIND = JobKind(
    collection="optimisations",
    kind=None,
    spec_model=OptimisationProblem,
    missing="optimisation job",
    check=check_problem,
    names={
        "submit": "submit_optimisation",
        "get": "get_optimisation",
        "list": "list_optimisations",
        "cancel": "cancel_optimisation",
    },
    summaries={
        "submit": "Submit an optimisation job",
        "get": "Status, progress, partial and final results",
        "list": "Optimisation jobs of this API key, newest first",
        "cancel": "Cancel an unfinished job (queued: at once; running: after the cases in progress), or "
        "remove a finished one and its files",
    },
)


def router(prefix: str) -> APIRouter:
    """The optimisation-job routes (under ``prefix``, ``/v1``)."""
    return job_router(prefix, KIND)
