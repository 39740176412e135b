"""The ``/v1`` routes, one module per resource; :func:`router` mounts them behind the API-key check.

==================  =====================================================================
``templates``       ``/templates``, ``/templates/{name}``, ``/templates/{name}/scene``, ``/scene-schema``
``curves``          ``/frequency-curve``
``diagnosis``       ``/diagnosis``
``optimisations``   ``/optimisations`` (jobs)
``topology``        ``/topology-searches`` (jobs)
``pareto``          ``/pareto-fronts`` (jobs)
``modes``           ``/modes``
``scenes``          ``/scenes/import``, ``/scenes/export`` (SPACAR .dat)
==================  =====================================================================

Adding a resource: a module with a ``router(prefix)`` returning an ``APIRouter`` under that prefix (the
routes carry their full path, which the access log names), added to :data:`RESOURCES`. Routes stay thin: validate (:mod:`..guards`), run the model in the worker pool
(:mod:`service.jobs.worker` through the runtime) or store a job, return wire models.
"""

from __future__ import annotations

from fastapi import APIRouter, Depends

from ..errors import ERRORS
from ..guards import key_checker
from ..settings import Settings
from . import curves, diagnosis, modes, optimisations, pareto, scenes, templates, topology

__all__ = ["PREFIX", "RESOURCES", "router"]

PREFIX = "/v1"
#: the resource modules, in the order their routes are matched
RESOURCES = (templates, curves, diagnosis, optimisations, topology, pareto, modes, scenes)


def router(settings: Settings) -> APIRouter:
    """Every ``/v1`` route, each checking the API key when keys are configured."""
    v1 = APIRouter(dependencies=[Depends(key_checker(settings))], responses={401: ERRORS[401]})
    for resource in RESOURCES:
        v1.include_router(resource.router(PREFIX))
    return v1
