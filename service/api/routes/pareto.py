"""``/v1/pareto-fronts``: Pareto fronts of worst-case parasitic frequency against drive stiffness (optim/pareto.py),
jobs of their own kind (an example spec, submit, status and result, list, cancel or remove)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.exceptions import RequestValidationError

# optim.pareto imports pydantic and numpy only at module level (no CasADi)
from ....optim.pareto import ParetoSpec, example_spec
from ..guards import check_problem
from .jobs import JobKind, job_router

__all__ = ["KIND", "router"]


def _check(spec: ParetoSpec) -> None:
    """The problem's checks at submission (optimisations' :func:`check_problem`), its fields under ``problem``."""
    try:
        check_problem(spec.problem)
    except RequestValidationError as exc:
        raise RequestValidationError(
            [{**e, "loc": ("body", "problem", *tuple(e["loc"])[1:])} for e in exc.errors()]
        ) from None


KIND = JobKind(
    collection="pareto-fronts",
    kind="pareto-front",
    spec_model=ParetoSpec,
    missing="Pareto front",
    check=_check,
    example=example_spec,
    names={
        "example": "pareto_example",
        "submit": "submit_pareto_front",
        "get": "get_pareto_front",
        "list": "list_pareto_fronts",
        "cancel": "cancel_pareto_front",
    },
    summaries={
        "example": "A small Pareto-front spec (a cross-spring pivot's length and thickness), to edit and submit",
        "submit": "Submit a Pareto front (worst-case parasitic frequency against drive stiffness, by "
        "epsilon-constraint with exact gradients, optionally checked by NSGA-II) as a job",
        "get": "Status, progress {done, total} of the cases of the current phase, and the front once succeeded",
        "list": "Pareto fronts of this API key, newest first",
        "cancel": "Cancel an unfinished Pareto front (running: after the cases in progress), or remove a finished one",
    },
)


def router(prefix: str) -> APIRouter:
    """The Pareto-front routes (under ``prefix``, ``/v1``)."""
    return job_router(prefix, KIND)
