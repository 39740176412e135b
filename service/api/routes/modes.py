"""``POST /v1/modes``: the deflected structure and the mode shapes at a stroke value (JSON, PNG or GIF).

The work runs in the runtime's worker pool like every heavy route (:func:`service.jobs.worker.modes`).
"""

from __future__ import annotations

import json

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import Response

from ...jobs import worker
from ...schemas import ModesOut, ModesRequest
from ..errors import HEAVY
from ..guards import TooCostly, admit
from ..runtime import runtime

__all__ = ["router"]

_MEDIA = ("image/gif", "image/png")


def router(prefix: str) -> APIRouter:
    """The modes route (under ``prefix``, ``/v1``)."""
    r = APIRouter(prefix=prefix)

    @r.post(
        "/modes",
        summary="Deflected structure and mode shapes at a stroke value",
        response_model=ModesOut,
        responses={
            200: {
                "content": {
                    "image/png": {"schema": {"type": "string", "format": "binary"}},
                    "image/gif": {"schema": {"type": "string", "format": "binary"}},
                },
                "description": "JSON by default; a 3D view with Accept: image/png; the mode animated "
                "with Accept: image/gif",
            },
            **HEAVY,
        },
    )
    async def modes(req: ModesRequest, request: Request) -> Response:
        accept = request.headers.get("accept", "")
        media = next((m for m in _MEDIA if m in accept), "application/json")
        try:  # the continuation walks to the stroke value in the scene's own steps: cost as for the whole curve
            scene = await admit(req.scene, None, runtime(request).settings)
        except TooCostly as exc:
            raise HTTPException(413, str(exc)) from None
        spec = {"scene": scene.model_dump(mode="json"), "at_stroke": req.at_stroke, "mode": req.mode, "media": media}
        body = await runtime(request).run(worker.modes, json.dumps(spec))
        return Response(body, media_type=media)

    return r
