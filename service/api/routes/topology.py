"""``/v1/topology-searches``: topology searches, jobs of their own kind (an example spec, submit, status and
result, list, cancel or remove)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.exceptions import RequestValidationError

from ....optim.topology.spec import TopologySpec, example_spec  # pydantic only (no CasADi)
from ..guards import nonfinite
from .jobs import JobKind, job_router

__all__ = ["KIND", "router"]


def _check(spec: TopologySpec) -> None:
    """Finite numbers (the rest, bounds and descriptors, was checked by TopologySpec itself)."""
    where = nonfinite(spec.model_dump())
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


KIND = JobKind(
    collection="topology-searches",
    kind="topology-search",
    spec_model=TopologySpec,
    missing="topology search",
    check=_check,
    example=example_spec,
    names={
        "example": "topology_example",
        "submit": "submit_topology_search",
        "get": "get_topology_search",
        "list": "list_topology_searches",
        "cancel": "cancel_topology_search",
    },
    summaries={
        "example": "The default topology-search spec (TopologySpec defaults), to edit and submit",
        "submit": "Submit a topology search: generate, screen, optimise and rank hinge topologies as a job",
        "get": "Status, progress {done, total} of the optimised cases, and the result once succeeded",
        "list": "Topology searches of this API key, newest first",
        "cancel": "Cancel an unfinished topology search (running: after the cases in progress), or remove a "
        "finished one",
    },
)


def router(prefix: str) -> APIRouter:
    """The topology-search routes (under ``prefix``, ``/v1``)."""
    return job_router(prefix, KIND)
