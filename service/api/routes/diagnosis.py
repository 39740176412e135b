"""``POST /v1/diagnosis``: exact-constraint diagnosis of a scene (D_cc, its SVD, the Table-1 class);
``POST /v1/state-space``: the linearised input-output model at a stroke point (model.linear)."""

from __future__ import annotations

import json
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import Response

from ...jobs import worker
from ...schemas import DiagnosisRequest, StateSpaceRequest
from ..errors import HEAVY
from ..guards import admit
from ..runtime import runtime

__all__ = ["router"]


def router(prefix: str) -> APIRouter:
    """The diagnosis route (under ``prefix``, ``/v1``)."""
    r = APIRouter(prefix=prefix)

    @r.post(
        "/diagnosis",
        summary="Exact-constraint diagnosis of a scene (D_cc, SVD, Table-1 class)",
        response_model=dict[str, Any],
        responses=HEAVY,
    )
    async def diagnosis(req: DiagnosisRequest, request: Request) -> Response:
        rt = runtime(request)
        scene = await admit(req.scene, [0.0], rt.settings)
        spec = {"scene": scene.model_dump(mode="json"), "at_stroke": req.at_stroke, "kinematic": req.kinematic}
        return Response(await rt.run(worker.diagnosis, json.dumps(spec)), media_type="application/json")

    @r.post(
        "/state-space",
        summary="Linearised input-output model (A, B, C, D) at a stroke point",
        response_model=dict[str, Any],
        responses=HEAVY,
    )
    async def state_space(req: StateSpaceRequest, request: Request) -> Response:
        rt = runtime(request)
        scene = await admit(req.scene, [0.0, req.at_stroke], rt.settings)  # validated off the event loop
        spec = {
            "scene": scene.model_dump(mode="json"),
            "at_stroke": req.at_stroke,
            "inputs": req.inputs,
            "outputs": req.outputs,
            "damping": req.damping,
            "modes": req.modes,
            "frequencies_hz": req.frequencies_hz,
        }
        return Response(await rt.run(worker.state_space, json.dumps(spec)), media_type="application/json")

    return r
