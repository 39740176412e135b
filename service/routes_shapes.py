"""``POST /v1/modes``: the deflected structure and the mode shapes at a stroke value (JSON, PNG or GIF).

A router of its own, mounted by ``create_app`` under ``/v1`` with the API-key dependency; the work runs in
the runtime's worker pool like every heavy route (:func:`service.worker.modes`).
"""

from __future__ import annotations

import json
from typing import Any

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import Response

from . import worker
from .schemas import ModesOut, ModesRequest, Problem

__all__ = ["router"]

_MEDIA = ("image/gif", "image/png")


def router() -> APIRouter:
    """The shapes routes (paths relative to the ``/v1`` prefix given when mounting)."""
    r = APIRouter()

    @r.post(
        "/modes",
        summary="Deflected structure and mode shapes at a stroke value",
        response_model=ModesOut,
        responses={200: {"content": {"image/png": {"schema": {"type": "string", "format": "binary"}},
                                     "image/gif": {"schema": {"type": "string", "format": "binary"}}},
                         "description": "JSON by default; a 3D view with Accept: image/png; the mode animated "
                                        "with Accept: image/gif"},
                   422: {"model": Problem, "description": "invalid input (field path and reason in errors)"},
                   413: {"model": Problem, "description": "request body too large"},
                   429: {"model": Problem, "description": "too many concurrent computations; see Retry-After"},
                   504: {"model": Problem, "description": "the computation exceeded the time limit"}},
    )
    async def modes(req: ModesRequest, request: Request) -> Response:
        accept = request.headers.get("accept", "")
        media = next((m for m in _MEDIA if m in accept), "application/json")
        from .app import TooCostly, _check_cost, _scene  # the same validation and cost limit as every heavy route

        scene = _scene(req.scene)
        try:  # the continuation walks to the stroke value in the scene's own steps: cost as for the whole curve
            _check_cost(scene, None, request.app.state.runtime.settings)
        except TooCostly as exc:
            raise HTTPException(413, str(exc)) from None
        spec = {"scene": scene.model_dump(mode="json"), "at_stroke": req.at_stroke, "mode": req.mode, "media": media}
        body = await request.app.state.runtime.run(worker.modes, json.dumps(spec))
        return Response(body, media_type=media)

    return r
